"""Static geom batching: fewer, larger meshes for faster software rendering.

A house has 100–200 static geoms; in a software rasteriser (Mesa llvmpipe)
the cost of a frame grows with the number of draw calls far more than with
the number of triangles. This module compiles a house's MJCF into a model
where every static geom keeps its collision role but is hidden from cameras
(visual group :data:`HIDDEN_GROUP`), and is drawn instead as part of one mesh
per (label, colour): all walls in one mesh, each room's chairs in one mesh,
and so on. The label part of the name (``class__roomtype__r<id>``) is kept,
so segmentation classes and the "see" test are unchanged.

Meshes are built with trimesh; cylinders and ellipsoids get few facets, which
is invisible at the benchmark's resolutions.
"""

from __future__ import annotations

import collections

import mujoco
import numpy as np
import trimesh

from leaps_mj.world import mjcf as house_mjcf

#: Visual group of geoms drawn through a batch mesh (hidden like the agent).
HIDDEN_GROUP = house_mjcf.AGENT_GROUP
_SECTIONS = 10


def _label(name: str) -> str:
    """The label part of a geom name: class, and room type and id if any."""
    parts = name.split("__")
    if len(parts) >= 3 and parts[2].startswith("r"):
        return "__".join(parts[:3])
    return parts[0]


def _primitive_mesh(gtype: int, size, pos) -> trimesh.Trimesh:
    if gtype == mujoco.mjtGeom.mjGEOM_BOX:
        mesh = trimesh.creation.box(extents=2 * np.asarray(size[:3]))
    elif gtype == mujoco.mjtGeom.mjGEOM_CYLINDER:
        mesh = trimesh.creation.cylinder(radius=size[0], height=2 * size[1], sections=_SECTIONS)
    elif gtype in (mujoco.mjtGeom.mjGEOM_ELLIPSOID, mujoco.mjtGeom.mjGEOM_SPHERE):
        mesh = trimesh.creation.icosphere(subdivisions=1)
        radii = size[:3] if gtype == mujoco.mjtGeom.mjGEOM_ELLIPSOID else [size[0]] * 3
        mesh.apply_scale(np.asarray(radii))
    else:
        raise ValueError(f"cannot batch geom type {gtype!r}: expected box, cylinder, sphere or ellipsoid")
    mesh.apply_translation(np.asarray(pos))
    return mesh


def compile_batched(xml: str) -> mujoco.MjModel:
    """Compiles house MJCF with its static world geoms batched for rendering.

    Args:
      xml: MJCF text from :func:`leaps_mj.world.mjcf.to_xml`.

    Returns:
      The compiled model: original geoms (hidden, colliding as before) plus
      one visual-only mesh geom per (label, colour).
    """
    spec = mujoco.MjSpec.from_string(xml)
    materials = {m.name: np.array(m.rgba) for m in spec.materials}
    batches: dict[tuple, list[trimesh.Trimesh]] = collections.defaultdict(list)
    for g in spec.worldbody.geoms:
        rgba = materials[g.material] if g.material else np.array(g.rgba)
        key = (_label(g.name), tuple(np.round(rgba, 3)))
        batches[key].append(_primitive_mesh(g.type, g.size, g.pos))
        g.group = HIDDEN_GROUP
    for k, ((label, rgba), meshes) in enumerate(sorted(batches.items())):
        mesh = trimesh.util.concatenate(meshes)
        spec.add_mesh(name=f"batch{k}", uservert=mesh.vertices.ravel().tolist(),
                      userface=mesh.faces.ravel().tolist(), inertia=mujoco.mjtMeshInertia.mjMESH_INERTIA_SHELL)
        spec.worldbody.add_geom(name=f"{label}__batch{k}", type=mujoco.mjtGeom.mjGEOM_MESH, meshname=f"batch{k}",
                                rgba=list(rgba), contype=0, conaffinity=0, group=0)
    return spec.compile()
