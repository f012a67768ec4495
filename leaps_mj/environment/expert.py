"""The geodesic expert: walks the shortest path with the 9 discrete actions.

It reads privileged state (the house's navigation grid, the agent's pose and
the task's target-pixel fraction), so it is an oracle: proof that every
episode is solvable and that the success test can be met, the teacher for
imitation warm starts, and (restricted to nearby targets) the "local expert"
sub-policy of the LEAPS evaluation.

Steering: the next waypoint is found by descending the geodesic distance
field for ``lookahead`` metres from the agent's cell; the agent turns (30° or
15°) until it faces the waypoint within ``_FACE_TOL`` and then moves forward.
Inside the target room it heads for a viewing zone near that room's
"see" objects, turns to face the nearest one and stays while the success test
holds.

:class:`ScanningGeodesicExpert` walks the same paths but, while the way
ahead lies outside the camera's horizontal field of view, always turns left
instead of the shorter way round: a teacher whose choice where the frames
cannot tell left from right is a fixed, learnable rule.
"""

from __future__ import annotations

import math

import numpy as np
import scipy.ndimage

from leaps_mj.world import navgrid, rooms

FORWARD, LEFT, RIGHT = 0, 3, 4
SMALL_FORWARD, SMALL_LEFT, SMALL_RIGHT, STAY = 5, 6, 7, 8
_FACE_TOL = math.radians(16)
_VIEW_RADIUS = 2.2  # metres from a see-object within which the agent looks at it
_SAFE_RADIUS = 0.35  # clearance of the expert's paths (the agent's radius is 0.2)


#: Neighbour offsets the expert's descent visits, in order (the first of equal cells wins).
_NEIGHBOURS = tuple((di, dj) for di in (-1, 0, 1) for dj in (-1, 0, 1))


def turn_action(err: float) -> int:
    """Rotation action reducing a heading error (radians, left positive)."""
    if abs(err) > math.radians(22.5):
        return LEFT if err > 0 else RIGHT
    return SMALL_LEFT if err > 0 else SMALL_RIGHT


def descend(field: np.ndarray, i: int, j: int, steps: int, neighbours=_NEIGHBOURS) -> tuple[int, int]:
    """The cell reached from (i, j) by up to ``steps`` moves to the lowest neighbour of a distance field.

    Each move goes to the first of ``neighbours`` (offsets, in the order given) whose value is lowest
    and below the current cell's; it stops early where no neighbour is lower.
    """
    for _ in range(steps):
        best = (field[i, j], i, j)
        for di, dj in neighbours:
            a, b = i + di, j + dj
            if 0 <= a < field.shape[0] and 0 <= b < field.shape[1] and field[a, b] < best[0]:
                best = (field[a, b], a, b)
        if best[1:] == (i, j):
            break
        _, i, j = best
    return i, j


def unstick(rng: np.random.Generator) -> int | None:
    """After a collision: half of the time a random unsticking move (left, right or a small step), else None."""
    if rng.random() < 0.5:
        return int(rng.choice([LEFT, RIGHT, SMALL_FORWARD]))
    return None


def steer(pose, waypoint, turn=turn_action) -> int:
    """Turn towards ``waypoint`` (with ``turn``) until facing it within ``_FACE_TOL``, then step towards it."""
    err = math.remainder(math.atan2(waypoint[1] - pose[1], waypoint[0] - pose[0]) - pose[2], 2 * math.pi)
    if abs(err) > _FACE_TOL:
        return turn(err)
    return FORWARD if np.hypot(waypoint[0] - pose[0], waypoint[1] - pose[1]) > 0.45 else SMALL_FORWARD


def half_view(env) -> float:
    """Half the horizontal field of view (radians) of the environment's first-person camera."""
    fovy = math.radians(float(env.physics.model.cam_fovy[0]))
    return math.atan(env.config.width / env.config.height * math.tan(fovy / 2))


class GeodesicExpert:
    """Shortest-path oracle for a :class:`leaps_mj.environment.roomnav.RoomNavEnvironment`.

    Args:
      env: the environment whose current episode it solves.
      seed: seed of the small random moves it makes when blocked.
      lookahead: metres of path ahead used as the steering waypoint.
    """

    #: Turn left whenever the way is out of view (:class:`ScanningGeodesicExpert`), not the shorter way.
    scan = False

    def __init__(self, env, seed: int = 0, lookahead: float = 0.6):
        self.env = env
        self.rng = np.random.default_rng(seed)
        self.lookahead = lookahead
        self._safe: dict[str, navgrid.NavGrid] = {}
        self._fields: dict[tuple, tuple[np.ndarray, np.ndarray, np.ndarray]] = {}
        self._episode = None  # the episode of the last new_episode() call, and its step
        self._steps = -1

    def reset(self) -> None:
        """Nothing to forget between episodes beyond the per-house cache."""

    def new_episode(self) -> bool:
        """Whether the environment's current step belongs to another episode than at the last call.

        For experts with a per-episode memory: the sub-policy trainer calls
        :meth:`act` every step without calling :meth:`reset`, so a new episode
        is detected from the task's episode spec (identity) and step counter.
        """
        task = self.env.task
        fresh = task.episode is not self._episode or task.steps < self._steps
        self._episode, self._steps = task.episode, task.steps
        return fresh

    def _safe_grid(self, hm):
        """The house's grid at a wider radius: paths keep off walls and corners."""
        key = hm.house.id
        if key not in self._safe:
            self._safe[key] = navgrid.NavGrid(hm.house, radius=_SAFE_RADIUS)
        return self._safe[key]

    def field(self, target: str, view: bool) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Steering field towards ``target``'s rooms (their viewing zones when ``view``), cached per house.

        Returns:
          :meth:`target_field` over every room of type ``target``.
        """
        hm = self.env.task.house_model
        key = (hm.house.id, target, view)
        if key not in self._fields:
            self._fields[key] = self.target_field(target, view)
        return self._fields[key]

    def target_field(self, target: str, view: bool, room_ids=None) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Steering field towards rooms of type ``target`` (their viewing zones when ``view``), uncached.

        Args:
          target: the room type (or ``indoor``).
          view: steer to the part of the rooms within :data:`_VIEW_RADIUS` of
            the type's see-objects (where there is one).
          room_ids: the rooms of that type to steer to (default: all of them).

        Returns:
          (distance field, nearest-cell indices: see :meth:`zone_field`;
          (n, 2) xy of the see-objects in those rooms).
        """
        hm = self.env.task.house_model
        grid = hm.grid
        goal_rooms = [r.id for r in hm.house.rooms if r.type == target and (room_ids is None or r.id in room_ids)]
        see = set(rooms.SEE_OBJECTS.get(target, ()))
        pts = np.array([g.pos[:2] for it in hm.house.items if it.room in goal_rooms
                        for g in it.geoms if g.cls in see]).reshape(-1, 2)
        zone = np.isin(grid.room_id, goal_rooms) & grid.free
        if view and len(pts):
            xs, ys = grid.cell_centers()
            near = np.zeros(grid.shape, dtype=bool)
            for px, py in pts:
                near |= np.hypot(xs - px, ys - py) <= _VIEW_RADIUS
            if (zone & near).any():
                zone = zone & near
        return (*self.zone_field(zone), pts)

    def zone_field(self, zone: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Steering field towards a mask of grid cells, uncached.

        Returns:
          (geodesic metres to ``zone`` on the wide-clearance grid, or on the
          house's grid where the wide one cannot reach it; index arrays of
          each cell's nearest cell where that field is finite).
        """
        hm = self.env.task.house_model
        dist = self._safe_grid(hm).distance_from(zone)
        if not np.isfinite(dist).any():
            dist = hm.grid.distance_from(zone)
        _, nearest = scipy.ndimage.distance_transform_edt(~np.isfinite(dist), return_indices=True)
        return dist, nearest

    def waypoint(self, field: np.ndarray, nearest: np.ndarray, xy) -> np.ndarray | None:
        """A point ``lookahead`` metres down ``field`` from ``xy``; None at the goal.

        Off the field (too near a wall for the wide-clearance grid) the
        waypoint is the nearest cell on it, which leads away from the wall.
        """
        grid = self.env.task.house_model.grid
        i, j = grid.to_cell(xy)
        if not np.isfinite(field[i, j]):
            i, j = int(nearest[0, i, j]), int(nearest[1, i, j])
            wp = grid.to_world((i, j))
            if np.hypot(*(wp - np.asarray(xy[:2]))) > 0.15:
                return wp
        if field[i, j] == 0:
            return None
        return grid.to_world(descend(field, i, j, int(self.lookahead / grid.cell)))

    def step_towards(self, target: str, view: bool, pose) -> int | None:
        """Action that follows the field to ``target`` from ``pose``; None at its goal."""
        field, nearest, _ = self.field(target, view)
        return self.follow(field, nearest, pose)

    def follow(self, field: np.ndarray, nearest: np.ndarray, pose) -> int | None:
        """Action that follows a steering field from ``pose``; None at its goal.

        After a collision it makes a random unsticking move half of the time.
        """
        wp = self.waypoint(field, nearest, pose[:2])
        if wp is None:
            return None
        if self.env.task.collision:
            action = unstick(self.rng)
            if action is not None:
                return action
        return steer(pose, wp, self.turn)

    def turn(self, err: float) -> int:
        """Rotation action towards a heading error (radians, left positive): the shorter way, or left when scanning."""
        if self.scan and abs(err) > half_view(self.env):
            return LEFT
        return turn_action(err)

    def act(self, timestep=None) -> int:
        """The expert's action for the environment's current state."""
        del timestep
        task = self.env.task
        pose = self.env.physics.agent_pose()
        target = task.episode.target
        if task.sees():
            return STAY
        if not rooms.SEE_OBJECTS.get(target):  # outdoor, indoor: being there suffices
            return self.step_towards(target, False, pose) or FORWARD
        action = self.step_towards(target, True, pose)
        if action is not None:
            return action
        # In the viewing zone: face the nearest see-object, step closer if aligned.
        pts = self.field(target, True)[2]
        if not len(pts):
            return LEFT
        d = np.hypot(pts[:, 0] - pose[0], pts[:, 1] - pose[1])
        px, py = pts[int(np.argmin(d))]
        err = math.remainder(math.atan2(py - pose[1], px - pose[0]) - pose[2], 2 * math.pi)
        if abs(err) > math.radians(10):
            return self.turn(err)
        return SMALL_FORWARD if d.min() > 1.0 else int(self.rng.choice([SMALL_LEFT, SMALL_RIGHT]))


class ScanningGeodesicExpert(GeodesicExpert):
    """The geodesic expert turning left whenever the way ahead is out of the camera's view.

    Where the waypoint lies beyond the horizontal field of view, the frames
    cannot show which way round is shorter, and the geodesic expert's labels
    there (left or right, by the map) are a coin flip to a learner: imitating
    them teaches it to dither. This teacher scans left until the way comes
    into view, then steers to it as the geodesic expert does, at the cost of
    at most about half a turn of extra rotation.
    """

    scan = True
