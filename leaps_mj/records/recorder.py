"""Episode records: one MCAP file per episode, with Foxglove schemas.

An :class:`EpisodeRecorder` follows a RoomNav episode step by step and writes
what a person needs to replay it in Foxglove (or with
:mod:`leaps_mj.replay`): the agent's first-person views, its pose, the house in
3D, the semantic signals, the agent's belief and plan, and the outcome.

Topics. Log times are simulation time: frame ``k`` (the observation after
``k`` actions; frame 0 is the start) is logged at ``k * 0.1 s``.

* ``/camera/segmentation`` (``foxglove.RawImage`` rgb8): class ids through
  :data:`SEG_PALETTE`.
* ``/camera/depth`` (``foxglove.RawImage`` 32FC1): metres, exactly the observation.
* ``/tf`` (``foxglove.FrameTransforms``): world -> agent (x, y, yaw), agent -> camera.
* ``/agent/pose`` (``foxglove.PoseInFrame``): the same pose in ``world``.
* ``/house`` (``foxglove.SceneUpdate``, once at 0): floors by room type, walls,
  doors, furniture, room names, the agent's body.
* ``/belief/graph`` (``foxglove.SceneUpdate``): the room-type graph above the
  house, edge opacity = belief, plan in red.
* ``/belief`` (JSON): edge beliefs (plottable), plan, sub-target.
* ``/semantic`` (JSON): room-type bits, their names, the target.
* ``/step`` (JSON): action, reward, return, collision, discount.
* ``/episode`` (JSON, at 0): episode spec, agent, run config.
* ``/outcome`` (JSON, at the last frame): success, length, sub-targets, ...

``/step`` has one message per action (frames 1..T); the image, pose and
semantic topics have T + 1 (frame 0 included); the ``/belief`` topics have a
message whenever the belief, plan or sub-target of the agent's ``info()``
changes (Foxglove shows the latest one at any time). The file also holds
metadata records ``episode``, ``run_config`` and ``outcome`` and attachments
``<house>.xml`` (the MJCF), ``<house>.json`` (:meth:`House.to_json`) and
``run_config.json``.

Encodings were measured on expert episodes (120x90, zstd chunks): raw rgb8
segmentation 0.33 KiB/frame vs 0.39 as PNG; raw 32FC1 depth 1.1 KiB/frame vs
0.76 as 16-bit millimetre PNG, which is lossy and costs 0.4 ms/frame to
encode. Raw images are kept: exact and cheap.

Files. A directory of records holds ``<agent>_<house>_<target>_<key>.mcap``
(see :func:`episode_key`), so a resumed evaluation replaces its own files and
worker processes never collide; ``keep`` selects all episodes, the failures,
or a sample of K.

Crash safety. An episode is written to ``<name>.mcap.part`` and renamed to
``<name>.mcap`` when it ends, so every ``.mcap`` is complete. Chunks are
small (:data:`CHUNK_SIZE`, about 6 frames), so a run killed mid-episode leaves
a ``.part`` file whose complete chunks ``python -m leaps_mj.replay --recover``
salvages. Same episode, same actions -> same message payloads (no wall clock
anywhere; JSON with sorted keys).
"""

from __future__ import annotations

import hashlib
import json
import math
import os
import pathlib
import re
from collections.abc import Mapping

import foxglove
import matplotlib
import mujoco
import numpy as np
from foxglove import messages as fm
from foxglove.mcap import MCAPWriteOptions

from leaps_mj.world import houses, rooms, topdown

#: Simulation time of one environment step (log times are ``step * STEP_NS``).
STEP_NS = 100_000_000
#: Target uncompressed chunk size: about 6 frames at 120x90 (images are ~74 KiB
#: a frame before compression), so a killed run loses at most ~6 steps. Measured
#: on a 300-step LEAPS episode: 32 KiB chunks 4.4 KiB/step, 128 KiB 3.2,
#: 512 KiB 2.4, 2 MiB 2.1 (zstd compresses better across more frames).
CHUNK_SIZE = 512 * 1024
#: Height of the belief graph drawn above the house (metres).
GRAPH_Z = rooms.WALL_HEIGHT + 1.5
#: Record format version (metadata ``episode.record_version``).
RECORD_VERSION = "1"

SEGMENTATION = "/camera/segmentation"
DEPTH = "/camera/depth"
TF = "/tf"
POSE = "/agent/pose"
HOUSE = "/house"
BELIEF_GRAPH = "/belief/graph"
BELIEF = "/belief"
SEMANTIC = "/semantic"
STEP = "/step"
EPISODE = "/episode"
OUTCOME = "/outcome"

_STRUCTURE_COLORS = {
    "empty": (0, 0, 0),
    "wall": (190, 190, 190),
    "floor": (105, 105, 105),
    "ceiling": (235, 235, 235),
    "door": (140, 86, 50),
    "fence": (110, 84, 60),
    "agent": (255, 0, 255),
}


def _palette() -> np.ndarray:
    """One distinct colour per segmentation class: fixed greys/browns for the
    structure, matplotlib's qualitative tab20 + tab20b for furniture."""
    furniture = [matplotlib.colormaps["tab20"](i) for i in range(20)]
    furniture += [matplotlib.colormaps["tab20b"](i) for i in range(0, 20, 2)]
    out = [_STRUCTURE_COLORS[c] for c in rooms.STRUCTURE_CLASSES]
    out += [tuple(round(255 * v) for v in furniture[i][:3]) for i in range(len(rooms.FURNITURE_CLASSES))]
    return np.array(out, dtype=np.uint8)


#: (NUM_SEG_CLASSES, 3) uint8 colour of each segmentation class.
SEG_PALETTE = _palette()
_PALETTE_CODES = SEG_PALETTE.astype(np.int64) @ np.array([1 << 16, 1 << 8, 1])
assert len(set(_PALETTE_CODES.tolist())) == rooms.NUM_SEG_CLASSES, "palette colours must be distinct"
_CODE_ORDER = np.argsort(_PALETTE_CODES)


def colorize(segmentation: np.ndarray) -> np.ndarray:
    """(H, W) class ids -> (H, W, 3) uint8 colours of :data:`SEG_PALETTE`."""
    return np.take(SEG_PALETTE, segmentation, axis=0)


def decolorize(rgb: np.ndarray) -> np.ndarray:
    """Inverse of :func:`colorize`.

    Raises:
      ValueError: if a pixel's colour is not in the palette.
    """
    codes = rgb.astype(np.int64) @ np.array([1 << 16, 1 << 8, 1])
    pos = np.searchsorted(_PALETTE_CODES[_CODE_ORDER], codes).clip(0, rooms.NUM_SEG_CLASSES - 1)
    ids = _CODE_ORDER[pos]
    bad = _PALETTE_CODES[ids] != codes
    if bad.any():
        i = np.argwhere(bad)[0]
        raise ValueError(f"pixel {tuple(i)} has colour {tuple(rgb[tuple(i)])}, not a segmentation class colour")
    return ids.astype(np.uint8)


def _stamp(t_ns: int) -> fm.Timestamp:
    return fm.Timestamp(t_ns // 1_000_000_000, t_ns % 1_000_000_000)


def _yaw_quat(yaw: float) -> fm.Quaternion:
    return fm.Quaternion(x=0.0, y=0.0, z=math.sin(yaw / 2), w=math.cos(yaw / 2))


def _color(rgb, a: float = 1.0) -> fm.Color:
    return fm.Color(r=float(rgb[0]), g=float(rgb[1]), b=float(rgb[2]), a=float(a))


def _pose(x: float, y: float, z: float, quat: fm.Quaternion | None = None) -> fm.Pose:
    return fm.Pose(position=fm.Vector3(x=float(x), y=float(y), z=float(z)),
                   orientation=quat or fm.Quaternion(w=1.0))


def _json_default(value):
    """JSON form of what ``json`` cannot encode itself: numpy values, specs."""
    if isinstance(value, np.ndarray):
        return value.tolist()
    if isinstance(value, np.generic):
        return value.item()
    if hasattr(value, "to_json"):
        return value.to_json()
    return str(value)


def _dumps(value) -> bytes:
    """Compact JSON with sorted keys: the same value always gives the same bytes."""
    return json.dumps(value, sort_keys=True, separators=(",", ":"), default=_json_default).encode()


# -- the house and the belief as 3D scenes -------------------------------------

def house_scene(house: houses.House, xml: str) -> fm.SceneUpdate:
    """The house as Foxglove primitives, from its compiled MJCF.

    Every static geom becomes a cube, cylinder or sphere (ellipsoid) with its
    material colour, grouped into one entity per class (floors carry the room
    colours of :data:`topdown.ROOM_COLORS`); ceilings are left out so the 3D
    panel looks inside. Room names float over the floors and a body with a
    heading arrow rides on the ``agent`` frame.
    """
    model = mujoco.MjModel.from_xml_string(xml)
    shapes: dict[str, dict[str, list]] = {}
    for g in range(model.ngeom):
        name = model.geom(g).name
        cls = name.split("__")[0]
        if model.geom_bodyid[g] != 0 or cls == "ceiling":
            continue
        gtype, size = mujoco.mjtGeom(int(model.geom_type[g])), model.geom_size[g]
        rgba = model.mat_rgba[model.geom_matid[g]] if model.geom_matid[g] >= 0 else model.geom_rgba[g]
        w, qx, qy, qz = model.geom_quat[g]
        pose = _pose(*model.geom_pos[g], fm.Quaternion(x=float(qx), y=float(qy), z=float(qz), w=float(w)))
        group = cls if cls in rooms.STRUCTURE_CLASSES else "furniture"
        prims = shapes.setdefault(group, {"cubes": [], "cylinders": [], "spheres": []})
        color = _color(rgba[:3], rgba[3])
        if gtype == mujoco.mjtGeom.mjGEOM_BOX:
            dims = fm.Vector3(x=2 * float(size[0]), y=2 * float(size[1]), z=2 * float(size[2]))
            prims["cubes"].append(fm.CubePrimitive(pose=pose, size=dims, color=color))
        elif gtype in (mujoco.mjtGeom.mjGEOM_CYLINDER, mujoco.mjtGeom.mjGEOM_CAPSULE):
            dims = fm.Vector3(x=2 * float(size[0]), y=2 * float(size[0]), z=2 * float(size[1]))
            prims["cylinders"].append(fm.CylinderPrimitive(pose=pose, size=dims, bottom_scale=1.0, top_scale=1.0,
                                                           color=color))
        elif gtype in (mujoco.mjtGeom.mjGEOM_ELLIPSOID, mujoco.mjtGeom.mjGEOM_SPHERE):
            r = size if gtype == mujoco.mjtGeom.mjGEOM_ELLIPSOID else np.repeat(size[0], 3)
            dims = fm.Vector3(x=2 * float(r[0]), y=2 * float(r[1]), z=2 * float(r[2]))
            prims["spheres"].append(fm.SpherePrimitive(pose=pose, size=dims, color=color))
        else:
            raise ValueError(f"geom {name!r} of house {house.id!r} has type {gtype.name}, expected a box, cylinder, "
                             "capsule, sphere or ellipsoid")
    entities = [fm.SceneEntity(timestamp=_stamp(0), frame_id="world", id=f"house/{group}", **prims)
                for group, prims in sorted(shapes.items())]
    labels = [fm.TextPrimitive(pose=_pose((r.rect[0] + r.rect[2]) / 2, (r.rect[1] + r.rect[3]) / 2, 0.3),
                               billboard=True, font_size=14.0, scale_invariant=True,
                               color=_color((0.1, 0.1, 0.1)), text=r.name)
              for r in house.indoor_rooms]
    entities.append(fm.SceneEntity(timestamp=_stamp(0), frame_id="world", id="house/labels", texts=labels))
    magenta = _color((1.0, 0.0, 1.0), 0.9)
    body = fm.CylinderPrimitive(pose=_pose(0, 0, 0.75),
                                size=fm.Vector3(x=2 * rooms.AGENT_RADIUS, y=2 * rooms.AGENT_RADIUS, z=1.5),
                                bottom_scale=1.0, top_scale=1.0, color=magenta)
    arrow = fm.ArrowPrimitive(pose=_pose(0, 0, 1.6), shaft_length=0.4, shaft_diameter=0.06,
                              head_length=0.2, head_diameter=0.15, color=magenta)
    entities.append(fm.SceneEntity(timestamp=_stamp(0), frame_id="agent", id="agent", frame_locked=True,
                                   cylinders=[body], arrows=[arrow]))
    return fm.SceneUpdate(entities=entities)


def graph_layout(house: houses.House) -> np.ndarray:
    """(9, 3) positions of the semantic graph's nodes above ``house``.

    A node floats over the centroid of its rooms; outdoor sits left of the
    lot and room types the house lacks are spread along its lower edge.
    """
    x0, y0, x1, y1 = house.lot
    pos = np.zeros((len(rooms.GRAPH_NODES), 3))
    pos[:, 2] = GRAPH_Z
    absent = []
    for n, node in enumerate(rooms.GRAPH_NODES):
        rects = np.array([r.rect for r in house.indoor_rooms if r.type == node]).reshape(-1, 4)
        if node == "outdoor":
            pos[n, :2] = (x0 - 1.5, (y0 + y1) / 2)
        elif len(rects):
            pos[n, :2] = ((rects[:, 0] + rects[:, 2]) / 2).mean(), ((rects[:, 1] + rects[:, 3]) / 2).mean()
        else:
            absent.append(n)
    for k, n in enumerate(absent):
        pos[n, :2] = (x0 + (x1 - x0) * (k + 1) / (len(absent) + 1), y0 - 1.5)
    return pos


def _edge_key(i: int, j: int) -> str:
    return f"{rooms.GRAPH_NODES[i]}__{rooms.GRAPH_NODES[j]}"


def belief_scene(layout: np.ndarray, belief: np.ndarray | None, plan: list[str], subtarget: str | None,
                 target: str, t_ns: int) -> fm.SceneUpdate:
    """The semantic graph at ``layout``: grey edges as opaque as their belief,
    the plan as a red line strip, nodes in room colours (target and
    sub-target enlarged)."""
    n = len(rooms.GRAPH_NODES)

    def point(i):
        return fm.Point3(x=float(layout[i, 0]), y=float(layout[i, 1]), z=float(layout[i, 2]))

    lines = []
    if belief is not None:
        pts, colors = [], []
        for i in range(n):
            for j in range(i + 1, n):
                c = _color((0.15, 0.35, 0.75), 0.05 + 0.9 * float(belief[i, j]))
                pts += [point(i), point(j)]
                colors += [c, c]
        lines.append(fm.LinePrimitive(type=fm.LinePrimitiveLineType.LineList, pose=_pose(0, 0, 0), thickness=0.06,
                                      points=pts, colors=colors))
    if len(plan) > 1:
        lines.append(fm.LinePrimitive(type=fm.LinePrimitiveLineType.LineStrip, pose=_pose(0, 0, 0.02),
                                      thickness=0.14, points=[point(rooms.room_index(p)) for p in plan],
                                      color=_color((0.85, 0.1, 0.1))))
    spheres, texts = [], []
    for i, node in enumerate(rooms.GRAPH_NODES):
        big = node in (target, subtarget)
        d = 0.7 if big else 0.45
        x, y, z = layout[i]
        spheres.append(fm.SpherePrimitive(pose=_pose(x, y, z), size=fm.Vector3(x=d, y=d, z=d),
                                          color=_color(topdown.ROOM_COLORS[node])))
        label = node + (" (target)" if node == target else " (sub-target)" if node == subtarget else "")
        texts.append(fm.TextPrimitive(pose=_pose(x, y, z + 0.5), billboard=True, font_size=12.0,
                                      scale_invariant=True, color=_color((0, 0, 0)), text=label))
    entity = fm.SceneEntity(timestamp=_stamp(t_ns), frame_id="world", id="belief", lines=lines, spheres=spheres,
                            texts=texts)
    return fm.SceneUpdate(entities=[entity])


# -- JSON channels ----------------------------------------------------------------

def _schema(name: str, properties: dict) -> foxglove.Schema:
    body = {"title": name, "type": "object", "properties": properties}
    return foxglove.Schema(name=name, encoding="jsonschema", data=json.dumps(body, sort_keys=True).encode())


_NUM = {"type": "number"}
_STR = {"type": "string"}
_JSON_SCHEMAS = {
    SEMANTIC: _schema("leaps_mj.Semantic", {
        "step": _NUM, "bits": {"type": "array", "items": _NUM},
        "rooms": {"type": "array", "items": _STR}, "target": _STR, "in_target": {"type": "boolean"}}),
    STEP: _schema("leaps_mj.Step", {
        "step": _NUM, "action": _NUM, "action_name": _STR, "reward": _NUM, "return": _NUM,
        "collision": _NUM, "discount": _NUM}),
    BELIEF: _schema("leaps_mj.Belief", {
        "step": _NUM, "subtarget": {"type": ["string", "null"]}, "plan": {"type": "array", "items": _STR},
        "plan_probability": {"type": ["number", "null"]},
        "edges": {"type": "object", "properties": {
            _edge_key(i, j): _NUM for i in range(len(rooms.GRAPH_NODES))
            for j in range(i + 1, len(rooms.GRAPH_NODES))}}}),
    EPISODE: _schema("leaps_mj.Episode", {
        "spec": {"type": "object"}, "agent": _STR, "key": _STR, "run_config": {"type": "object"}}),
    OUTCOME: _schema("leaps_mj.Outcome", {
        "success": {"type": "boolean"}, "steps": _NUM, "return": _NUM,
        "subtargets": {"type": "array", "items": _STR}}),
}


def parse_mode(keep: str) -> int | None:
    """Checks a record mode ("all", "failures", "sample:K"): K, or None if not sampling.

    Raises:
      ValueError: naming the bad mode and the accepted ones.
    """
    if keep in ("all", "failures"):
        return None
    prefix, _, k = keep.partition(":")
    if prefix == "sample" and k.isdigit() and int(k) > 0:
        return int(k)
    raise ValueError(f"record mode {keep!r}: expected 'all', 'failures' or 'sample:K' with K a positive integer")


def episode_key(spec, agent_name: str, seed: int = 0) -> str:
    """16 hex digits identifying (agent, episode, seed): the end of a record's file name.

    Read as a number in [0, 1) it is also the episode's sampling priority.
    """
    blob = _dumps({"agent": agent_name, "spec": spec, "seed": seed})
    return hashlib.sha256(blob).hexdigest()[:16]


_KEY_RE = re.compile(r"_([0-9a-f]{16})\.mcap$")


class EpisodeRecorder:
    """Writes RoomNav episodes to MCAP files, one per episode.

    Use it as the evaluation observer (``begin(env, spec, agent)``, then
    ``step(timestep, action, info)`` after every environment step, then
    ``end(result)``), or around a loop of your own::

        with record.EpisodeRecorder("runs/records", env) as rec:
            ts = env.reset()
            rec.begin()
            while not ts.last():
                action = policy(ts)
                ts = env.step(action)
                rec.step(ts, action)
            rec.end()

    ``step`` takes the timestep *produced by* ``action``. A FIRST timestep may
    be passed too (action None): it then becomes frame 0; otherwise frame 0
    is read from the environment at ``begin``.

    Files in a directory are named ``<agent>_<house>_<target>_<key>.mcap``
    with ``key = episode_key(spec, agent, seed)``: the same episode recorded
    again (a resumed evaluation) replaces its file, and processes writing to
    one directory never collide.

    Args:
      out: a directory, or a single ``.mcap`` path (one episode only).
      env: the :class:`leaps_mj.environment.roomnav.RoomNavEnvironment` (default for ``begin``).
      run_config: JSON-able description of the run (attached to every file).
      keep: "all"; "failures" (files of successful episodes are removed at
        ``end``); or "sample:K": the K episodes of smallest key (a uniform
        sample, the same whatever the order or the number of processes
        recording into the directory). An episode whose key is above the
        directory's K-th smallest is not written at all; a file pushed out
        of the K smallest is deleted.
      seed: seed of the keys, hence of the sample.
      chunk_size: MCAP chunk size in bytes (what a killed run can lose).

    Raises:
      ValueError: for a bad ``keep`` mode or a misused protocol (step before
        begin, begin twice, a second episode into a single-file path).
    """

    def __init__(self, out: str | os.PathLike, env=None, run_config: Mapping | None = None, keep: str = "all",
                 seed: int = 0, chunk_size: int = CHUNK_SIZE):
        self.out = pathlib.Path(out)
        self.single = self.out.suffix == ".mcap"
        self.env = env
        self.run_config = json.loads(_dumps(dict(run_config or {})))
        self.keep = keep
        self.seed = seed
        self._sample = parse_mode(keep)
        if self._sample and self.single:
            raise ValueError(f"record mode {keep!r} samples episodes: expected a directory, not {str(out)!r}")
        self._options = MCAPWriteOptions(chunk_size=int(chunk_size), compression_threads=0)
        self._ctx = foxglove.Context()
        self._images = {t: foxglove.channels.RawImageChannel(t, context=self._ctx) for t in (SEGMENTATION, DEPTH)}
        self._tf = foxglove.channels.FrameTransformsChannel(TF, context=self._ctx)
        self._pose = foxglove.channels.PoseInFrameChannel(POSE, context=self._ctx)
        self._scenes = {t: foxglove.channels.SceneUpdateChannel(t, context=self._ctx) for t in (HOUSE, BELIEF_GRAPH)}
        self._json = {t: foxglove.Channel(t, schema=s, message_encoding="json", context=self._ctx)
                      for t, s in _JSON_SCHEMAS.items()}
        self._house_scenes: dict[str, fm.SceneUpdate] = {}
        self.episodes = 0
        self._writer = None
        self._path: pathlib.Path | None = None
        self._active = False

    # -- protocol ---------------------------------------------------------------
    def begin(self, env=None, spec=None, agent=None) -> pathlib.Path | None:
        """Starts an episode (call after the environment's reset).

        Args:
          env: the environment (default: the one given at construction).
          spec: its :class:`EpisodeSpec` (default: ``env.episode``).
          agent: the agent, for its ``name`` (optional).

        Returns:
          The path the episode will be written to, or None when the sample
          leaves it out.
        """
        if self._active:
            raise ValueError("begin() called while an episode is being recorded: call end() first")
        env = env if env is not None else self.env
        if env is None or not hasattr(env, "house_model"):
            raise ValueError(f"env {env!r}: expected a leaps_mj RoomNavEnvironment (given here or to the recorder)")
        spec = spec if spec is not None else env.episode
        if spec is None:
            raise ValueError("no episode spec: reset the environment before begin()")
        if self.single and self.episodes:
            raise ValueError(f"{self.out} holds one episode: give a directory to record several")
        self.episodes += 1
        self._active = True
        self._agent_name = str(getattr(agent, "name", "agent"))
        key = episode_key(spec, self._agent_name, self.seed)
        name = f"{self._agent_name}_{spec.house}_{spec.target}_{key}.mcap"
        self._path = self.out if self.single else self.out / name
        if self._sample and not self._in_sample(key):
            self._path = None
            return None
        hm = env.house_model(spec.house)
        self._path.parent.mkdir(parents=True, exist_ok=True)
        self._part = self._path.with_name(self._path.name + ".part")
        self._writer = foxglove.open_mcap(self._part, allow_overwrite=True, context=self._ctx,
                                          writer_options=self._options)
        self._spec = spec
        self._layout = graph_layout(hm.house)
        self._frame = 0
        self._return = 0.0
        self._last = None
        self._subtargets: list[str] = []
        self._belief_key = None
        self._first_obs = env.task.get_observation(env.physics) if hasattr(env, "task") else None
        episode = {"spec": spec.to_json(), "agent": self._agent_name, "key": key, "run_config": self.run_config}
        meta = {"house": spec.house, "target": spec.target, "agent": self._agent_name, "key": key,
                "start": json.dumps(list(spec.start)), "geodesic": json.dumps(spec.geodesic),
                "plan_length": json.dumps(spec.plan_length), "record_version": RECORD_VERSION}
        self._writer.write_metadata("episode", meta)
        self._writer.write_metadata("run_config", {k: json.dumps(v, sort_keys=True)
                                                   for k, v in self.run_config.items()})
        for name, media, data in ((f"{spec.house}.xml", "application/xml", hm.xml.encode()),
                                  (f"{spec.house}.json", "application/json", _dumps(hm.house.to_json())),
                                  ("run_config.json", "application/json", _dumps(self.run_config))):
            self._writer.attach(log_time=0, create_time=0, name=name, media_type=media, data=data)
        if spec.house not in self._house_scenes:
            self._house_scenes[spec.house] = house_scene(hm.house, hm.xml)
        self._scenes[HOUSE].log(self._house_scenes[spec.house], log_time=0)
        self._json[EPISODE].log(_dumps(episode), log_time=0)
        return self._path

    def step(self, timestep, action=None, info: Mapping | None = None) -> None:
        """Records the timestep that ``action`` produced, with the agent's ``info()``.

        Raises:
          ValueError: before ``begin``, for a non-FIRST timestep without an
            action, or a malformed belief.
        """
        if not self._active:
            raise ValueError("step() called outside an episode: call begin() first")
        if self._path is None:
            return
        if timestep.first():
            if self._frame:
                raise ValueError("a FIRST timestep in the middle of an episode: call end() and begin() first")
            self._first_obs = None
            self._log_frame(timestep.observation, None, None, None, info)
            return
        if action is None:
            raise ValueError(f"step {self._frame + 1}: a non-FIRST timestep needs the action that produced it")
        if self._first_obs is not None:
            self._log_frame(self._first_obs, None, None, None, None)
            self._first_obs = None
        self._frame += 1
        self._last = timestep
        self._log_frame(timestep.observation, int(action), timestep.reward, timestep.discount, info)

    def end(self, result: Mapping | None = None) -> pathlib.Path | None:
        """Ends the episode: writes the outcome, closes and renames the file.

        Args:
          result: the evaluation's result dict (merged into the outcome; its
            ``success`` wins over the recorder's own reading, which is
            "terminated with discount 0").

        Returns:
          The finished file, or None when it is not kept.
        """
        if not self._active:
            raise ValueError("end() called outside an episode: call begin() first")
        self._active = False
        if self._path is None:
            return None
        if self._first_obs is not None:
            self._log_frame(self._first_obs, None, None, None, None)
        success = bool(self._last is not None and self._last.last() and self._last.discount == 0.0)
        outcome = {"success": success, "steps": self._frame, "return": self._return,
                   "subtargets": self._subtargets, "agent": self._agent_name,
                   "house": self._spec.house, "target": self._spec.target, **dict(result or {})}
        self._json[OUTCOME].log(_dumps(outcome), log_time=self._frame * STEP_NS)
        self._writer.write_metadata("outcome", {k: _dumps(v).decode() for k, v in outcome.items()})
        self._writer.close()
        self._writer = None
        if self.keep == "failures" and outcome["success"]:
            self._part.unlink()
            return None
        os.replace(self._part, self._path)
        if self._sample:
            for old in self._sample_files()[self._sample:]:
                old.unlink(missing_ok=True)
            if not self._path.exists():
                return None
        return self._path

    def close(self) -> None:
        """Closes an episode left open (it stays a valid ``.mcap.part``, marked incomplete)."""
        if self._writer is not None:
            self._writer.write_metadata("outcome", {"complete": "false", "steps": str(self._frame)})
            self._writer.close()
            self._writer = None
        self._active = False

    def __enter__(self) -> "EpisodeRecorder":
        return self

    def __exit__(self, *exc) -> None:
        self.close()

    # -- internals ------------------------------------------------------------------
    def _sample_files(self) -> list[pathlib.Path]:
        """The directory's records, by increasing key."""
        files = [p for p in self.out.glob("*.mcap") if _KEY_RE.search(p.name)] if self.out.is_dir() else []
        return sorted(files, key=lambda p: _KEY_RE.search(p.name).group(1))

    def _in_sample(self, key: str) -> bool:
        """Whether an episode of this key is among the K smallest with the directory's records."""
        keys = [_KEY_RE.search(p.name).group(1) for p in self._sample_files()]
        return key in keys or len(keys) < self._sample or key < keys[self._sample - 1]

    def _log_frame(self, obs, action, reward, discount, info) -> None:
        k = self._frame
        t = k * STEP_NS
        stamp = _stamp(t)
        seg = np.asarray(obs["segmentation"])
        depth = np.ascontiguousarray(obs["depth"], dtype=np.float32)
        h, w = seg.shape
        self._images[SEGMENTATION].log(fm.RawImage(timestamp=stamp, frame_id="camera", width=w, height=h,
                                                   encoding="rgb8", step=3 * w, data=colorize(seg).tobytes()),
                                       log_time=t)
        self._images[DEPTH].log(fm.RawImage(timestamp=stamp, frame_id="camera", width=w, height=h,
                                            encoding="32FC1", step=4 * w, data=depth.tobytes()), log_time=t)
        x, y, yaw = (float(v) for v in obs["pose"])
        self._tf.log(fm.FrameTransforms(transforms=[
            fm.FrameTransform(timestamp=stamp, parent_frame_id="world", child_frame_id="agent",
                              translation=fm.Vector3(x=x, y=y, z=0.0), rotation=_yaw_quat(yaw)),
            fm.FrameTransform(timestamp=stamp, parent_frame_id="agent", child_frame_id="camera",
                              translation=fm.Vector3(z=rooms.AGENT_CAMERA_HEIGHT),
                              rotation=fm.Quaternion(w=1.0)),
        ]), log_time=t)
        self._pose.log(fm.PoseInFrame(timestamp=stamp, frame_id="world", pose=_pose(x, y, 0.0, _yaw_quat(yaw))),
                       log_time=t)
        bits = [int(b) for b in obs["semantic"]]
        target = self._spec.target
        self._json[SEMANTIC].log(_dumps({
            "step": k, "bits": bits, "rooms": [r for r, b in zip(rooms.ROOM_TYPES, bits) if b],
            "target": target, "in_target": bool(bits[rooms.room_index(target)])}), log_time=t)
        if action is not None:
            self._return += float(reward or 0.0)
            self._json[STEP].log(_dumps({
                "step": k, "action": action, "action_name": rooms.ACTION_NAMES[action], "reward": reward,
                "return": self._return, "collision": int(obs["collision"]), "discount": discount}), log_time=t)
        self._log_belief(k, t, info or {})

    def _log_belief(self, k: int, t: int, info: Mapping) -> None:
        """Publishes the agent's belief, plan and sub-target when they change.

        (Foxglove shows the latest message at any time, seeking included; the
        plotted edge beliefs step at each change.)
        """
        subtarget = info.get("subtarget")
        plan = [str(p) for p in info.get("plan") or []]
        belief = info.get("belief")
        if belief is not None:
            belief = np.asarray(belief, dtype=np.float64)
            n = len(rooms.GRAPH_NODES)
            if belief.shape != (n, n):
                raise ValueError(f"info['belief'] has shape {belief.shape}, expected ({n}, {n}) over "
                                 f"{list(rooms.GRAPH_NODES)}")
        if subtarget is not None and (not self._subtargets or self._subtargets[-1] != subtarget):
            self._subtargets.append(str(subtarget))
        key = (subtarget, tuple(plan), None if belief is None else belief.tobytes())
        if key == self._belief_key or (self._belief_key is None and key == (None, (), None)):
            return
        self._belief_key = key
        msg = {"step": k, "subtarget": subtarget, "plan": plan, "plan_probability": None}
        if belief is not None:
            msg["edges"] = {_edge_key(i, j): float(belief[i, j]) for i in range(n) for j in range(i + 1, n)}
            if len(plan) > 1:
                idx = [rooms.room_index(p) for p in plan]
                msg["plan_probability"] = float(np.prod([belief[a, b] for a, b in zip(idx, idx[1:])]))
        self._json[BELIEF].log(_dumps(msg), log_time=t)
        self._scenes[BELIEF_GRAPH].log(belief_scene(self._layout, belief, plan, subtarget, self._spec.target, t),
                                       log_time=t)


def recorder_for_evaluation(out_dir: str | os.PathLike, mode: str = "all", seed: int = 0,
                            run_config: Mapping | None = None) -> EpisodeRecorder:
    """An :class:`EpisodeRecorder` to pass as ``observer`` to ``episodes.run_episode``.

    Args:
      out_dir: directory of the records (one file per kept episode).
      mode: "all", "failures" or "sample:K" (see :class:`EpisodeRecorder`).
      seed: seed of the sample.
      run_config: the evaluation's arguments, attached to every file.
    """
    if pathlib.Path(out_dir).suffix == ".mcap":
        raise ValueError(f"record directory {str(out_dir)!r}: expected a directory, not a .mcap file")
    return EpisodeRecorder(out_dir, run_config=run_config, keep=mode, seed=seed)
