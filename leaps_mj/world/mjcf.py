"""House → MJCF scene, with PyMJCF (``dm_control.mjcf``).

Every geom's name carries its label, ``<class>__<room type>__r<room id>__…``
for furniture and per-room surfaces, ``<class>__…`` for walls, fences and
door lintels, so the environment can map a rendered segment id to an object
class and a room without any side table. Floors are thin boxes (planes are
several times slower to render in software). The agent, a kinematic cylinder
with a first-person camera, comes from ``assets/agent.xml``.

Collision filtering: static geoms have ``contype=1, conaffinity=2`` and the
agent ``contype=2, conaffinity=1``, so MuJoCo reports agent–scene contacts
only (no static–static pairs); floors, rugs and foliage never collide.
"""

from __future__ import annotations

from dm_control import mjcf

from leaps_mj.world import houses, rooms, topdown

AGENT_XML = houses.ASSETS_DIR / "agent.xml"
#: Visual group of the agent's own body, hidden from its camera.
AGENT_GROUP = 3
_STATIC = dict(contype=1, conaffinity=2)
_GHOST = dict(contype=0, conaffinity=0)
_LINTEL_BOTTOM = 2.1
_FLOOR_THICKNESS = 0.05
_PRECISION = 5


def _box(rect, z0, z1):
    x0, y0, x1, y1 = rect
    return dict(
        type="box",
        pos=[(x0 + x1) / 2, (y0 + y1) / 2, (z0 + z1) / 2],
        size=[(x1 - x0) / 2, (y1 - y0) / 2, (z1 - z0) / 2],
    )


def build(house: houses.House) -> mjcf.RootElement:
    """The MJCF model of ``house`` with the agent at the origin."""
    root = mjcf.RootElement(model=house.id)
    root.compiler.angle = "radian"
    root.option.timestep = 0.01
    root.visual.__getattr__("global").offwidth = 640
    root.visual.__getattr__("global").offheight = 480
    root.visual.map.znear = 0.002
    root.visual.map.zfar = 5.0
    root.visual.headlight.ambient = [0.45, 0.45, 0.45]
    root.visual.headlight.diffuse = [0.5, 0.5, 0.5]
    for t, c in topdown.ROOM_COLORS.items():
        root.asset.add("material", name=f"floor_{t}", rgba=[*c, 1])
    root.asset.add("material", name="wall", rgba=[0.93, 0.91, 0.86, 1])
    root.asset.add("material", name="ceiling", rgba=[0.98, 0.98, 0.98, 1])
    root.asset.add("material", name="fence", rgba=[0.45, 0.35, 0.25, 1])
    root.asset.add("material", name="garage_door", rgba=[0.85, 0.3, 0.1, 1])
    root.asset.add("material", name="door", rgba=[0.55, 0.35, 0.2, 1])
    wb = root.worldbody
    wb.add("light", name="sun", directional="true", pos=[0, 0, 10], dir=[0.3, 0.2, -1], castshadow="false",
           diffuse=[0.5, 0.5, 0.5])

    for r in sorted(house.rooms, key=lambda r: r.type != "outdoor"):
        # The yard's floor sits a millimetre under the rooms' floors.
        top = -0.001 if r.type == "outdoor" else 0.0
        wb.add("geom", name=f"floor__{r.type}__r{r.id}", material=f"floor_{r.type}",
               **_box(r.rect, top - _FLOOR_THICKNESS, top), **_GHOST)
        if r.type != "outdoor":
            wb.add("geom", name=f"ceiling__{r.type}__r{r.id}", material="ceiling",
                   **_box(r.rect, rooms.WALL_HEIGHT, rooms.WALL_HEIGHT + 0.05), **_GHOST)
    garage = [r.id for r in house.rooms if r.type == "garage"]
    for i, w in enumerate(house.walls):
        name = f"{w.cls}__w{i}" if w.cls != "garage_door" else f"garage_door__garage__r{garage[0]}__w{i}"
        wb.add("geom", name=name, material=w.cls, **_box(w.rect, 0.0, w.height), **_STATIC)
        if w.cls == "garage_door":
            # The wall above the garage door, up to the ceiling.
            wb.add("geom", name=f"wall__w{i}__lintel", material="wall",
                   **_box(w.rect, w.height, rooms.WALL_HEIGHT), **_STATIC)
    t = rooms.WALL_THICKNESS
    for i, d in enumerate(house.doors):
        cx, cy = d.center
        half = d.width / 2 + t / 2
        rect = (cx - half, cy - t / 2, cx + half, cy + t / 2) if d.axis == "x" else (cx - t / 2, cy - half, cx + t / 2, cy + half)
        wb.add("geom", name=f"door__d{i}", material="door", **_box(rect, _LINTEL_BOTTOM, rooms.WALL_HEIGHT), **_STATIC)
    for it in house.items:
        collide = _GHOST if it.footprint is None else _STATIC
        for g in it.geoms:
            # Foliage above a trunk does not block (the trunk alone is the footprint).
            ghost = it.key == "tree" and g.shape == "ellipsoid"
            wb.add("geom", name=g.name, type=g.shape, pos=list(g.pos), size=list(g.size), rgba=list(g.rgba),
                   **(_GHOST if ghost else collide))

    agent = mjcf.from_path(str(AGENT_XML))
    wb.attach(agent)
    return root


def to_xml(house: houses.House) -> str:
    """The MJCF text of ``house`` (deterministic: same house, same bytes)."""
    return build(house).to_xml_string(precision=_PRECISION)
