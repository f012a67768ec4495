"""RoomNav: reach a room of a given type, seeing segmentation and depth.

A dm_control task with the dm_env API, in the layout of dm_control's suite:
a :class:`Physics` subclass that alone touches raw MuJoCo arrays, a
:class:`RoomNav` task, and :func:`load` returning a
:class:`RoomNavEnvironment` (a ``control.Environment`` that swaps in the
cached physics of the episode's house at each reset).

The agent is kinematic, as in House3D: an action proposes a new pose (move
0.5 m / turn 30° and their small variants); the move is carried out in 0.1 m
increments and stops at the last pose where MuJoCo reports no contact between
the agent's cylinder and the scene, which is then a collision.

Episodes. Each reset either samples (house, target type, start pose) from the
split with the task's seeded RNG, or runs an :class:`EpisodeSpec` given to
:meth:`RoomNavEnvironment.reset_to` (the fixed evaluation episodes).

Success ("see", from the paper): the agent is in a room of the target type
and at least 4.5 % of the frame shows that room type's objects *in that room*
for 3 consecutive steps; for outdoor, being there suffices. The untyped
``indoor`` node (hallways, closets) may also be a target, for training the
sub-policy LEAPS runs when its plan goes through a hallway: being in untyped
indoor space (all semantic bits off) suffices, and its ``target`` one-hot is
all zero. The episode then
terminates (discount 0); the horizon truncates it (discount 1).
"""

from __future__ import annotations

import collections
import dataclasses
import json
import math
import pathlib

import mujoco
import numpy as np
import scipy.ndimage
from dm_control import mujoco as dm_mujoco
from dm_control.rl import control
from dm_control.suite import base
from dm_env import specs

from leaps_mj.environment import batching, render
from leaps_mj.world import dataset as dataset_lib
from leaps_mj.world import houses, navgrid, rooms

_SUBSTEP = 0.1  # metres per collision-checked increment of a move
_NO_DISTANCE = 1e3  # geodesic distance reported where the target is unreachable
#: Depth reported where the view ray hits nothing (sky) or beyond: metres.
MAX_DEPTH = 20.0


@dataclasses.dataclass(frozen=True)
class EnvConfig:
    """Configuration of a RoomNav environment.

    Attributes:
      width, height: image size (paper: 120x90).
      horizon: steps before truncation (paper evaluates 300 / 500 / 1000).
      reward: "shaped" (training reward of the original release) or "sparse"
        (1 on success, else 0: evaluation).
      rgb: also render a colour image (a second render pass).
      success_fraction: fraction of pixels of target objects for "see".
      success_steps: consecutive steps the see test must hold.
      targets: room types that may be drawn as targets (default: all 8;
        ``indoor`` is allowed too, see the module docstring).
      max_start_distance: if set, sampled starts are at most this many
        geodesic metres from the target (curriculum / short training episodes).
      min_start_distance: sampled starts are at least this far (metres).
      max_start_doors: if set, sampled starts lie in rooms at most this many
        doors (room-to-room hops) from a room of the target type: the
        neighbouring-room task LEAPS hands its sub-policies.
      cache_size: compiled houses kept (physics + renderer).
      pixels: render segmentation and depth. False gives a "blind" fast
        environment (images all zero, the see test cannot pass except for
        outdoor) for work that needs only poses and semantic bits, such as
        learning the prior by random exploration.
    """

    width: int = 120
    height: int = 90
    horizon: int = 1000
    reward: str = "shaped"
    rgb: bool = False
    success_fraction: float = 0.045
    success_steps: int = 3
    targets: tuple[str, ...] = rooms.ROOM_TYPES
    max_start_distance: float | None = None
    min_start_distance: float = 0.0
    max_start_doors: int | None = None
    cache_size: int = 32
    pixels: bool = True

    def __post_init__(self):
        if not (isinstance(self.width, int) and isinstance(self.height, int)) or not (
            8 <= self.width <= 640 and 8 <= self.height <= 480
        ):
            raise ValueError(f"resolution {self.width}x{self.height}: expected integers in 8..640 x 8..480")
        if not isinstance(self.horizon, int) or self.horizon < 1:
            raise ValueError(f"horizon {self.horizon!r}: expected a positive integer")
        if self.reward not in ("shaped", "sparse"):
            raise ValueError(f"reward {self.reward!r}: expected 'shaped' or 'sparse'")
        if not 0.0 < self.success_fraction < 1.0:
            raise ValueError(f"success_fraction {self.success_fraction!r}: expected a value in (0, 1)")
        if not isinstance(self.success_steps, int) or self.success_steps < 1:
            raise ValueError(f"success_steps {self.success_steps!r}: expected a positive integer")
        object.__setattr__(self, "targets", tuple(self.targets))
        for t in self.targets:
            if t not in rooms.GRAPH_NODES:
                raise ValueError(f"unknown target room type {t!r}; expected one of {list(rooms.GRAPH_NODES)}")
        if not self.targets:
            raise ValueError("targets is empty: expected at least one room type")
        if self.max_start_doors is not None and (isinstance(self.max_start_doors, bool) or not isinstance(
                self.max_start_doors, int) or self.max_start_doors < 1):
            raise ValueError(f"max_start_doors {self.max_start_doors!r}: expected a positive integer or None")
        if self.max_start_distance is not None and self.max_start_distance <= self.min_start_distance:
            raise ValueError(
                f"max_start_distance {self.max_start_distance!r} must exceed min_start_distance "
                f"{self.min_start_distance!r}"
            )


@dataclasses.dataclass(frozen=True)
class EpisodeSpec:
    """One episode: house, start pose (x, y, yaw radians) and target room type."""

    house: str
    start: tuple[float, float, float]
    target: str
    geodesic: float | None = None
    plan_length: int | None = None

    def to_json(self) -> dict:
        return dataclasses.asdict(self)

    @classmethod
    def from_json(cls, data: dict) -> "EpisodeSpec":
        try:
            spec = cls(house=str(data["house"]), start=tuple(float(v) for v in data["start"]),
                       target=str(data["target"]), geodesic=data.get("geodesic"),
                       plan_length=data.get("plan_length"))
        except (KeyError, TypeError, ValueError) as e:
            raise ValueError(f"not an episode spec: {data!r} ({e})") from None
        if len(spec.start) != 3:
            raise ValueError(f"episode start {spec.start!r}: expected (x, y, yaw)")
        rooms.room_index(spec.target)
        return spec


def load_episodes(path: str | pathlib.Path) -> list[EpisodeSpec]:
    """Reads a JSON-lines file of episode specs.

    Raises:
      ValueError: naming the file and line of a malformed entry.
    """
    path = pathlib.Path(path)
    if not path.exists():
        raise ValueError(f"episode file {str(path)!r} does not exist")
    out = []
    for n, line in enumerate(path.read_text().splitlines(), 1):
        if not line.strip():
            continue
        try:
            out.append(EpisodeSpec.from_json(json.loads(line)))
        except (json.JSONDecodeError, ValueError) as e:
            raise ValueError(f"{path}:{n}: {e}") from None
    return out


class HouseModel:
    """Everything precomputed once per house: grid, labels, room lookups.

    Attributes:
      house: the :class:`houses.House`.
      xml: its MJCF text.
      grid: its :class:`navgrid.NavGrid`.
      seg_lut: geom id + 1 → segmentation class (index 0: nothing hit).
      see_lut: (K, ngeom + 1) bool, geom counts for the "see" test of type k.
      node_lut: geom id + 1 → graph node of the room the geom belongs to
        (floors, ceilings, furniture; ``len(GRAPH_NODES)`` for walls, doors
        and nothing hit): the per-pixel room labels of training's auxiliary losses.
      room_lut: geom id + 1 → id of the room the geom belongs to (-1 for none):
        which rooms a frame reveals, for the observable expert.
    """

    def __init__(self, house: houses.House, xml: str, model: mujoco.MjModel):
        self.house = house
        self.xml = xml
        self.grid = navgrid.NavGrid(house)
        ngeom = model.ngeom
        self.seg_lut = np.zeros(ngeom + 1, dtype=np.uint8)
        # One row per graph node; the indoor row stays empty (nothing to see).
        self.see_lut = np.zeros((len(rooms.GRAPH_NODES), ngeom + 1), dtype=bool)
        self.node_lut = np.full(ngeom + 1, len(rooms.GRAPH_NODES), dtype=np.uint8)
        self.room_lut = np.full(ngeom + 1, -1, dtype=np.int16)
        for g in range(ngeom):
            parts = model.geom(g).name.split("__")
            cls = parts[0].split("/")[-1]
            self.seg_lut[g + 1] = rooms.seg_class_index(cls)
            if len(parts) >= 3 and parts[2].startswith("r"):
                room_type = parts[1]
                self.room_lut[g + 1] = int(parts[2][1:])
                if room_type in rooms.GRAPH_NODES:
                    self.node_lut[g + 1] = rooms.room_index(room_type)
                if room_type in rooms.SEE_OBJECTS and cls in rooms.SEE_OBJECTS[room_type]:
                    self.see_lut[rooms.room_index(room_type), g + 1] = True
        self.agent_geom = mujoco.mj_name2id(model, mujoco.mjtObj.mjOBJ_GEOM, "agent/agent__shell")
        pad = rooms.WALL_THICKNESS / 2
        indoor = house.indoor_rooms
        # (x0, y0, x1, y1, room-type index) per indoor room, widened by half a wall; plain
        # tuples, as semantic_bits runs every step over a handful of rooms.
        self._rects = tuple((r.rect[0] - pad, r.rect[1] - pad, r.rect[2] + pad, r.rect[3] + pad,
                             rooms.room_index(r.type)) for r in indoor)
        self._has_yard = any(r.type == "outdoor" for r in house.rooms)
        self._distance_maps: dict[str, np.ndarray] = {}
        self._plan_lengths: dict[str, dict[int, int]] = {}
        self._door_masks: dict[tuple[str, int], np.ndarray] = {}

    def within_doors(self, target: str, doors: int) -> np.ndarray:
        """Grid mask of the rooms at most ``doors`` room-to-room hops from a room of type ``target``."""
        key = (target, doors)
        if key not in self._door_masks:
            lengths = {r.id: self.plan_length(r.id, target) for r in self.house.rooms}
            near = [i for i, n in lengths.items() if n is not None and n <= doors]
            self._door_masks[key] = np.isin(self.grid.room_id, near)
        return self._door_masks[key]

    def semantic_bits(self, x: float, y: float) -> np.ndarray:
        """Room-type bits of a point: one per type of the rooms it is in.

        In a doorway (within half a wall of two rooms) both rooms' bits are on;
        in untyped indoor space all bits are zero; in the yard, outdoor.
        """
        bits = np.zeros(rooms.NUM_ROOM_TYPES, dtype=np.uint8)
        indoors = False
        for x0, y0, x1, y1, kind in self._rects:
            if x0 <= x <= x1 and y0 <= y <= y1:
                indoors = True
                if kind < rooms.NUM_ROOM_TYPES:
                    bits[kind] = 1
        if not indoors and self._has_yard:
            bits[rooms.room_index("outdoor")] = 1
        return bits

    @staticmethod
    def in_node(bits: np.ndarray, node: int) -> bool:
        """Whether semantic bits place the agent in graph node ``node``.

        The ``indoor`` node is untyped indoor space: no bit on (the yard sets
        the outdoor bit).
        """
        return bool(bits[node]) if node < rooms.NUM_ROOM_TYPES else not bits.any()

    def distance_map(self, target: str) -> np.ndarray:
        """Geodesic metres to the nearest room of ``target`` from every cell.

        Cells the agent's centre cannot occupy (too near a wall on the
        conservative grid) take the value of their nearest free cell.
        """
        if target not in self._distance_maps:
            dist = self.grid.distance_to_type(target)
            _, (ii, jj) = scipy.ndimage.distance_transform_edt(~self.grid.free, return_indices=True)
            filled = dist[ii, jj]
            self._distance_maps[target] = np.where(np.isfinite(filled), filled, _NO_DISTANCE)
        return self._distance_maps[target]

    def geodesic(self, xy, target: str) -> float:
        """Geodesic metres from a world point to the nearest ``target`` room."""
        return float(self.distance_map(target)[self.grid.to_cell(xy)])

    def room_at(self, xy) -> int:
        """Id of the room containing a point (-1 outside the lot)."""
        return int(self.grid.room_id[self.grid.to_cell(xy)])

    def plan_length(self, room_id: int, target: str) -> int | None:
        """Fewest room-to-room hops from a room to a room of type ``target`` (None: unreachable)."""
        if target not in self._plan_lengths:
            self._plan_lengths[target] = self.house.plan_lengths(target)
        return self._plan_lengths[target].get(room_id)


class Physics(dm_mujoco.Physics):
    """Physics of a house with a kinematic agent.

    ``step`` does not integrate dynamics: the task sets the agent's pose and
    the physics only updates kinematics, cameras and contacts.
    """

    def _reload_from_data(self, data) -> None:
        super()._reload_from_data(data)
        # The raw mujoco structs: the per-step calls below skip dm_control's wrapper attribute lookups.
        self._raw_model, self._raw_data = self.model.ptr, self.data.ptr

    def step(self, nstep: int = 1) -> None:
        del nstep
        self.forward_kinematics()

    def forward_kinematics(self) -> None:
        mujoco.mj_kinematics(self._raw_model, self._raw_data)
        mujoco.mj_camlight(self._raw_model, self._raw_data)

    def agent_pose(self) -> np.ndarray:
        """(x, y, yaw) of the agent."""
        return self._raw_data.qpos[:3].copy()

    def set_agent_pose(self, pose) -> None:
        self._raw_data.qpos[:3] = pose
        self.forward_kinematics()

    def agent_in_contact(self, agent_geom: int) -> bool:
        """Whether the agent's cylinder touches any scene geom at its pose."""
        m, d = self._raw_model, self._raw_data
        mujoco.mj_kinematics(m, d)
        mujoco.mj_collision(m, d)
        return bool(d.ncon and (d.contact.geom == agent_geom).any())


def _coerce_action(action) -> int:
    """The action as an int in [0, 9), or a ValueError naming what was given."""
    if type(action) is int and 0 <= action < rooms.NUM_ACTIONS:  # the common case, checked cheaply
        return action
    arr = np.asarray(action)
    if arr.shape != () or not (np.issubdtype(arr.dtype, np.integer)):
        raise ValueError(
            f"invalid action {action!r} (dtype {arr.dtype}, shape {arr.shape}): expected an integer "
            f"scalar in [0, {rooms.NUM_ACTIONS}) — one of {list(rooms.ACTION_NAMES)}"
        )
    a = int(arr)
    if not 0 <= a < rooms.NUM_ACTIONS:
        raise ValueError(f"invalid action {a}: expected an integer in [0, {rooms.NUM_ACTIONS})")
    return a


class RoomNav(base.Task):
    """The RoomNav task: reach and see a room of the target type."""

    def __init__(self, env: "RoomNavEnvironment", config: EnvConfig, random=None):
        super().__init__(random=random)
        self._env = env
        self.config = config
        self.episode: EpisodeSpec | None = None
        self.next_spec: EpisodeSpec | None = None
        self.house_model: HouseModel | None = None

    # -- specs ---------------------------------------------------------------
    def action_spec(self, physics):
        del physics
        return specs.DiscreteArray(rooms.NUM_ACTIONS, dtype=np.int32, name="action")

    def observation_spec(self, physics):
        del physics
        c = self.config
        spec = collections.OrderedDict(
            segmentation=specs.BoundedArray((c.height, c.width), np.uint8, 0, rooms.NUM_SEG_CLASSES - 1,
                                            name="segmentation"),
            depth=specs.BoundedArray((c.height, c.width), np.float32, 0.0, MAX_DEPTH, name="depth"),
            semantic=specs.BoundedArray((rooms.NUM_ROOM_TYPES,), np.uint8, 0, 1, name="semantic"),
            target=specs.BoundedArray((rooms.NUM_ROOM_TYPES,), np.uint8, 0, 1, name="target"),
            collision=specs.BoundedArray((), np.uint8, 0, 1, name="collision"),
            pose=specs.Array((3,), np.float32, name="pose"),
        )
        if c.rgb:
            spec["rgb"] = specs.Array((c.height, c.width, 3), np.uint8, name="rgb")
        return spec

    # -- episode -------------------------------------------------------------
    def initialize_episode(self, physics):
        hm = self.house_model
        spec = self.episode
        physics.set_agent_pose(spec.start)
        self.target_index = rooms.room_index(spec.target)
        self.target_onehot = rooms.target_onehot(spec.target)
        # Segment index → whether its pixels count for seeing the target.
        self._see_mask = self._env.segment_luts[1][self.target_index]
        self.collision = False
        self.steps = 0
        self.success_streak = 0
        self.success = False
        xy = spec.start[:2]
        self.distance = hm.geodesic(xy, spec.target)
        self.bits = hm.semantic_bits(*xy)
        self.in_target = hm.in_node(self.bits, self.target_index)
        self._render(physics)
        self.prev_fraction = self.target_fraction

    def before_step(self, action, physics):
        a = _coerce_action(action)
        _, fwd, left, yaw_deg = rooms.ACTIONS[a]
        x, y, yaw = physics.agent_pose().tolist()
        yaw = math.remainder(yaw + math.radians(yaw_deg), 2 * math.pi)
        dist = math.hypot(fwd, left)
        self.collision = False
        if dist > 0:
            heading = yaw + math.atan2(left, fwd)
            n = max(1, math.ceil(dist / _SUBSTEP - 1e-9))
            ok = (x, y)
            qpos, agent_geom = physics.data.ptr.qpos, self.house_model.agent_geom
            for k in range(1, n + 1):
                cand = (x + math.cos(heading) * dist * k / n, y + math.sin(heading) * dist * k / n)
                qpos[:3] = (*cand, yaw)
                if physics.agent_in_contact(agent_geom):
                    self.collision = True
                    break
                ok = cand
            qpos[:3] = (*ok, yaw)
        else:
            physics.data.ptr.qpos[2] = yaw

    def after_step(self, physics):
        self.steps += 1
        self._render(physics)
        hm = self.house_model
        x, y, _ = physics.agent_pose().tolist()
        self.prev_distance, self.distance = self.distance, hm.geodesic((x, y), self.episode.target)
        self.was_in_target = self.in_target
        self.bits = hm.semantic_bits(x, y)
        self.in_target = hm.in_node(self.bits, self.target_index)
        self.success_streak = self.success_streak + 1 if self.sees() else 0
        self.success = self.success_streak >= self.config.success_steps

    def sees(self) -> bool:
        """The "see" test at the current state: in the target room and, where the target has
        see-objects, at least ``success_fraction`` of the frame on them (outdoor, indoor: being there)."""
        nothing_to_see = not rooms.SEE_OBJECTS.get(self.episode.target)
        return self.in_target and (nothing_to_see or self.target_fraction >= self.config.success_fraction)

    def _render(self, physics):
        if not self.config.pixels:
            shape = (self.config.height, self.config.width)
            self.segments = np.zeros(shape, dtype=np.intp)
            self.segmentation = np.zeros(shape, dtype=np.uint8)
            self.depth = np.zeros(shape, dtype=np.float32)
            self.target_fraction = 0.0
            return
        renderer = self._env.renderer
        seg, depth = renderer.render_segments(physics.data.ptr)
        # ndarray.take: the fastest per-pixel table lookup for these sizes (fancy indexing and
        # bincount cost several times more); seg indexes the tables, whose length is ngeom + 1.
        self.segments = seg  # segment indices, for per-pixel tables of other uses (training labels)
        self.segmentation = self._env.segment_luts[0].take(seg)
        self.depth = np.minimum(depth, MAX_DEPTH, out=depth)
        self.target_fraction = np.count_nonzero(self._see_mask.take(seg)) / seg.size

    def get_observation(self, physics):
        pose = physics.agent_pose()
        # Every frame is a fresh array (see _render), so it is handed out without a copy.
        obs = collections.OrderedDict(
            segmentation=self.segmentation,
            depth=self.depth,
            semantic=self.bits.copy(),
            target=self.target_onehot.copy(),
            collision=np.uint8(self.collision),
            pose=pose.astype(np.float32),
        )
        if self.config.rgb:
            obs["rgb"] = self._env.renderer.render_rgb(physics.data.ptr)
        return obs

    def get_reward(self, physics):
        del physics
        if self.config.reward == "sparse":
            return float(self.success)
        return self.shaped_reward()

    def shaped_reward(self) -> float:
        """The original release's "new" training reward (see DESIGN.md)."""
        if self.success:
            return 10.0
        r = 0.0
        delta = self.prev_distance - self.distance
        r += min(max(delta, -0.5), 0.5)
        if delta <= 1e-6:
            r -= 0.1
        if self.was_in_target and not self.in_target:
            r -= 0.1
        if self.in_target:
            r += 0.05
        frac = min(self.target_fraction / 0.10, 1.0)
        r += frac - min(self.prev_fraction / 0.10, 1.0)
        self.prev_fraction = self.target_fraction
        if self.collision:
            r -= 0.3
        return r

    def get_termination(self, physics):
        del physics
        if self.success:
            return 0.0
        if self.steps >= self.config.horizon:
            return 1.0
        return None


class RoomNavEnvironment(control.Environment):
    """A ``control.Environment`` over a split of houses.

    Compiled houses (physics, renderer, navigation grid) are cached, so an
    episode in another house costs a lookup after the first visit.
    """

    def __init__(self, house_files: list[pathlib.Path], config: EnvConfig, seed=None):
        if not house_files:
            raise ValueError("no houses given")
        self.config = config
        self._house_files = {p.stem: p for p in house_files}
        self._cache: collections.OrderedDict[str, tuple] = collections.OrderedDict()
        self._gl = render.make_context(config.width, config.height)
        render.track(self)
        self.renderer = None
        self.segment_luts = None
        self._task = RoomNav(self, config, random=seed)
        try:
            first = self._activate(sorted(self._house_files)[0])
        except Exception:
            self.close()
            raise
        super().__init__(first, self._task, time_limit=float("inf"), n_sub_steps=1)

    # -- houses ----------------------------------------------------------------
    @property
    def house_ids(self) -> list[str]:
        return sorted(self._house_files)

    def house_model(self, house_id: str) -> HouseModel:
        """The precomputed :class:`HouseModel` of a house of this split."""
        self._activate(house_id, switch=False)
        return self._cache[house_id][1]

    def _activate(self, house_id: str, switch: bool = True) -> Physics:
        if house_id not in self._house_files:
            raise ValueError(f"unknown house {house_id!r}; this environment has {len(self._house_files)} "
                             f"houses, e.g. {self.house_ids[:3]}")
        if house_id not in self._cache:
            path = self._house_files[house_id]
            house = houses.House.load(path.with_suffix(".json"))
            xml_path = path.with_suffix(".xml")
            try:
                xml = xml_path.read_text()
                physics = Physics.from_model(dm_mujoco.wrapper.MjModel(batching.compile_batched(xml)))
            except OSError as e:
                raise ValueError(f"cannot read house model {str(xml_path)!r}: {e.strerror}") from None
            except Exception as e:  # noqa: BLE001 - MuJoCo raises ValueError/Error subclasses
                raise ValueError(f"house model {str(xml_path)!r} does not compile: {e}") from None
            hm = HouseModel(house, xml, physics.model.ptr)
            rend = render.SegDepthRenderer(physics.model.ptr, self.config.width, self.config.height,
                                           context=self._gl)
            self._cache[house_id] = (physics, hm, rend)
            while len(self._cache) > self.config.cache_size:
                _, (_, _, old) = self._cache.popitem(last=False)
                old.close()
        self._cache.move_to_end(house_id)
        physics, hm, rend = self._cache[house_id]
        if switch:
            self._physics = physics
            self.renderer = rend
            self._task.house_model = hm
            # Segment index → class, → counts for "see", → room node and → room id, via the scene's geoms.
            geoms = rend.segment_geoms + 1
            self.segment_luts = (hm.seg_lut[geoms], hm.see_lut[:, geoms], hm.node_lut[geoms], hm.room_lut[geoms])
        return physics

    # -- episodes --------------------------------------------------------------
    def reset(self):
        """Starts an episode: the spec given to :meth:`reset_to`, or a sampled one."""
        spec = self._task.next_spec or self.sample_episode()
        self._task.next_spec = None
        self._activate(spec.house)
        self._task.episode = spec
        return super().reset()

    def seed(self, seed: int) -> None:
        """Reseeds the task's RNG (episode sampling), e.g. for gymnasium's ``reset(seed=...)``."""
        if isinstance(seed, bool) or not isinstance(seed, (int, np.integer)) or seed < 0:
            raise ValueError(f"seed {seed!r}: expected an integer >= 0")
        self._task._random = np.random.RandomState(int(seed))  # noqa: SLF001 - dm_control keeps no setter

    def reset_to(self, spec: EpisodeSpec | dict):
        """Starts the given episode (house id, start pose, target type)."""
        if isinstance(spec, dict):
            spec = EpisodeSpec.from_json(spec)
        rooms.room_index(spec.target)
        hm = self.house_model(spec.house)
        if spec.target not in hm.house.room_types:
            raise ValueError(f"house {spec.house!r} has no room of type {spec.target!r}")
        self._task.next_spec = spec
        return self.reset()

    def sample_episode(self) -> EpisodeSpec:
        """Draws (house, target, start) with the task's RNG.

        The start is a free cell outside every room of the target type (and
        within the configured distance bounds), with a uniform heading.
        """
        rng = self._task.random
        c = self.config
        ids = self.house_ids
        for _ in range(1000):
            hid = ids[rng.randint(len(ids))]
            hm = self.house_model(hid)
            present = [t for t in c.targets if t in hm.house.room_types]
            if not present:
                continue
            target = present[rng.randint(len(present))]
            dist = hm.distance_map(target)
            ok = hm.grid.free & ~hm.grid.room_mask(target) & (dist >= max(c.min_start_distance, 0.1))
            ok &= dist < _NO_DISTANCE
            if c.max_start_distance is not None:
                ok &= dist <= c.max_start_distance
            if c.max_start_doors is not None:
                ok &= hm.within_doors(target, c.max_start_doors)
            cells = np.flatnonzero(ok.ravel())
            if cells.size == 0:
                continue
            cell = np.unravel_index(cells[rng.randint(cells.size)], ok.shape)
            xy = hm.grid.to_world(cell)
            yaw = float(rng.uniform(-math.pi, math.pi))
            return EpisodeSpec(hid, (float(xy[0]), float(xy[1]), yaw), target,
                               geodesic=float(dist[cell]),
                               plan_length=hm.plan_length(hm.room_at(xy), target))
        raise RuntimeError("could not sample an episode: no house offers a start for the configured targets")

    @property
    def episode(self) -> EpisodeSpec | None:
        """The spec of the current episode."""
        return self._task.episode

    def close(self):
        for _, _, rend in self._cache.values():
            rend.close()
        self._cache.clear()
        if self._gl is not None:
            self._gl.free()
            self._gl = None


def load(dataset: str = dataset_lib.CANONICAL, split: str = "train", seed=0, houses_dir=None, **config) -> RoomNavEnvironment:
    """Builds a RoomNav environment over a split of a house dataset.

    Args:
      dataset: dataset name under ``houses/`` (or a path when ``houses_dir``).
      split: "train", "valid" or "test".
      seed: seed of the task's RNG (episode sampling).
      houses_dir: explicit folder of ``<id>.json`` + ``<id>.xml`` files.
      **config: fields of :class:`EnvConfig`.

    Raises:
      ValueError: for an unknown split, a missing dataset or a bad config value.
    """
    unknown = set(config) - {f.name for f in dataclasses.fields(EnvConfig)}
    if unknown:
        raise ValueError(f"unknown config keys {sorted(unknown)}; expected fields of EnvConfig: "
                         f"{[f.name for f in dataclasses.fields(EnvConfig)]}")
    cfg = EnvConfig(**config)
    if houses_dir is not None:
        files = sorted(pathlib.Path(houses_dir).glob("*.json"))
        if not files:
            raise ValueError(f"no house files (*.json) in {str(houses_dir)!r}")
    else:
        files = dataset_lib.list_houses(dataset, split)
    return RoomNavEnvironment(files, cfg, seed=seed)
