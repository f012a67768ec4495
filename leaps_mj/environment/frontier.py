"""Frontier goals: where to walk next, read off the agent's own map alone.

The map-goal network (:mod:`leaps_mj.learning.goal_policy`) learns *where* to
go from a teacher that reads the house's map; from one door away the map
the agent has built does not show which door that teacher prefers, and every
network of sessions 8–10 plateaued at choosing a goal the teacher would not
(docs/training.md). :class:`FrontierGoals` is the classical answer to the same
question, frontier-based exploration (Yamauchi, 1997) with a target detector:

* **Target mapped.** Once cells of the target's see-objects (for ``outdoor``
  its cues) are on the map, the goal is the nearest free floor cell within
  :data:`TARGET_REACH` metres of them, as near them as it can be (so that
  it stands in their room, not behind a wall); there the
  :class:`leaps_mj.environment.map_navigation.GoalDriver` faces them and stays.
  Several room types share see-object classes, so a table may stand in
  another room. With the map's semantic channels, a target cell with an
  object of another type's own classes (a sofa, a bed, a toilet) within
  :data:`CONTRADICT_RADIUS` metres is not a goal: the table next to a sofa
  stands in a living room; objects of classes only the target's type has
  count :data:`OWN_BONUS` metres nearer. A target goal not reached within
  :data:`PATIENCE` steps, or stood at for :data:`TARGET_PATIENCE` steps with
  the run still going (the see test did not end it), is rejected, and so are
  the target cells within :data:`REJECT_RADIUS` metres of it.
* **Explore.** Otherwise the goal is the frontier cell (mapped floor next to
  unmapped space) of least path length over the cells not mapped blocked,
  at least :data:`MIN_FRONTIER` metres away, with a frontier near a mapped
  door counted :data:`DOOR_BONUS` metres nearer: new rooms lie beyond doors.
  Cells around where the agent stood count as mapped (the camera does not see
  the floor at its feet).

A goal is kept until it is reached, stops being a frontier, or
:data:`PATIENCE` steps pass, so the walk does not flip between two frontiers.
It reads only the map (the agent's frames, depth and pose), never the house.
"""

from __future__ import annotations

import math

import numpy as np
import scipy.ndimage

from leaps_mj.environment import map_navigation, mapping

#: Metres from the target's mapped objects within which a floor cell is a goal.
TARGET_REACH = 1.25
#: Steps at a target goal, the run still going, after which that goal is rejected.
TARGET_PATIENCE = 8
#: Metres around a rejected goal within which target cells are no longer goals.
REJECT_RADIUS = 1.25
#: Metres within which another room type's own object contradicts a target cell.
CONTRADICT_RADIUS = 2.0
#: Metres of path a target goal's metre nearer the objects is worth.
APPROACH_WEIGHT = 3.0
#: Metres by which floor near objects of the target's own classes counts nearer.
OWN_BONUS = 3.0
#: Metres within which a frontier is too near to be a goal.
MIN_FRONTIER = 1.0
#: Metres by which a frontier within a cell of a mapped door counts nearer.
DOOR_BONUS = 2.0
#: Steps after which a goal is chosen afresh.
PATIENCE = 24
#: Metres from a goal within which it is reached.
REACHED = 0.5
#: Steps of turning on the spot (30° each: a full circle) when there is nowhere to go, before looking again.
LOOK_STEPS = 12
#: Cells around the agent's trail counted as mapped.
TRAIL = 2

_EIGHT = np.ones((3, 3), bool)
_FLOOR, _DOOR, _TARGET, _VISITED = (mapping.CHANNELS.index(c) for c in ("floor", "door", "target", "visited"))


class FrontierGoals:
    """Chooses a driver's goals by frontier exploration with a target detector (see the module docstring).

    Call :meth:`reset` at the start of each run and :meth:`cell` every step
    after the driver has observed the step's frame.
    """

    def __init__(self):
        self.reset()

    def reset(self) -> None:
        """A new run: no goal, nothing rejected."""
        self.goal: np.ndarray | None = None
        self.kind: str | None = None  # "target", "frontier" or "look"
        self._age = 0
        self._waited = 0
        self._rejected: list[np.ndarray] = []

    def cell(self, driver: map_navigation.GoalDriver) -> int:
        """The goal for this step, as a row-major index into the driver's egocentric window."""
        mapper, pose = driver.mapper, driver.pose
        grid = mapper.grid
        here = np.array(mapper.cells(pose[0], pose[1])[:2]).clip(0, mapping.GRID - 1)
        targets = self._targets(mapper)
        self._age += 1
        rejected = len(self._rejected)
        if self.goal is not None and self._keep(mapper, pose, targets):
            return self._window(mapper, pose)
        if len(self._rejected) > rejected:
            targets = self._targets(mapper)  # less what _keep just rejected
        dist = self._distances(mapper, here)
        floor = (grid[_FLOOR] | grid[_DOOR]).astype(bool) & np.isfinite(dist)
        self.goal, self.kind = None, None
        if targets.any():
            # Floor as close to the objects as can be reached, so as to stand in their room, not behind a wall;
            # objects of the target's own classes (a toilet, not a sink) count nearer.
            reach = scipy.ndimage.distance_transform_edt(~targets) * mapping.CELL
            near = floor & (reach <= TARGET_REACH)
            own = scipy.ndimage.binary_dilation(self._confirmed(mapper, targets),
                                                iterations=round(TARGET_REACH / mapping.CELL))
            if near.any():
                cost = dist + APPROACH_WEIGHT * reach - OWN_BONUS * own
                self._set(mapper, np.where(near, cost, np.inf), "target")
            else:  # no floor mapped by them yet: head for the nearest (the planner takes unmapped cells as free)
                rows, cols = np.indices(targets.shape)
                self._set(mapper, np.where(targets, np.hypot(rows - here[0], cols - here[1]), np.inf), "target")
        if self.goal is None:
            known = grid[:len(mapping.CHANNELS)].any(0) | mapper.blocked
            known |= scipy.ndimage.binary_dilation(grid[_VISITED].astype(bool), iterations=TRAIL)
            frontier = floor & scipy.ndimage.binary_dilation(~known, structure=_EIGHT) & (dist >= MIN_FRONTIER)
            if frontier.any():
                door = scipy.ndimage.binary_dilation(grid[_DOOR].astype(bool), structure=_EIGHT)
                self._set(mapper, np.where(frontier, dist - DOOR_BONUS * door, np.inf), "frontier")
        if self.goal is None:  # nothing to go to: stand and look around
            self.goal, self.kind, self._age = np.asarray(pose[:2], np.float64), "look", 0
        return self._window(mapper, pose)

    @staticmethod
    def _distances(mapper: mapping.EgoMapper, here: np.ndarray) -> np.ndarray:
        """Path metres from the agent's cell over the cells not mapped blocked (with clearance), computed
        over the mapped part of the grid and a margin (inf elsewhere)."""
        mapped = mapper.grid.any(0) | mapper.blocked
        rows, cols = np.nonzero(mapped)
        r0, r1 = max(0, min(rows.min(), here[0]) - 2), min(mapping.GRID, max(rows.max(), here[0]) + 3)
        c0, c1 = max(0, min(cols.min(), here[1]) - 2), min(mapping.GRID, max(cols.max(), here[1]) + 3)
        free = ~scipy.ndimage.binary_dilation(mapper.blocked[r0:r1, c0:c1], iterations=map_navigation.CLEARANCE)
        dist = np.full((mapping.GRID, mapping.GRID), np.inf)
        dist[r0:r1, c0:c1] = map_navigation.path_distances(free, (here[0] - r0, here[1] - c0)) * mapping.CELL
        return dist

    @staticmethod
    def _semantic(mapper: mapping.EgoMapper) -> tuple[np.ndarray, np.ndarray] | None:
        """(cells of the target type's see-object classes, cells of any other type's), from the map's
        semantic channels; None without them or for a target without see-objects (``outdoor``, ``indoor``)."""
        grid, target = mapper.grid, mapper.target
        if len(grid) == len(mapping.CHANNELS) or target not in mapping.SEMANTIC:
            return None
        semantic = grid[len(mapping.CHANNELS):].astype(bool)
        own = mapping.SEMANTIC.index(target)
        return semantic[own], np.delete(semantic, own, axis=0).any(0)

    def _contradicted(self, mapper: mapping.EgoMapper) -> np.ndarray:
        """Cells within :data:`CONTRADICT_RADIUS` of an object of a class that other room types have and
        the target has not (all False without the semantic channels)."""
        channels = self._semantic(mapper)
        if channels is None:
            return np.zeros(mapper.grid.shape[1:], bool)
        own, others = channels
        return scipy.ndimage.binary_dilation(others & ~own, iterations=round(CONTRADICT_RADIUS / mapping.CELL))

    def _confirmed(self, mapper: mapping.EgoMapper, targets: np.ndarray) -> np.ndarray:
        """The target cells of classes no other room type has (all of them for a target without
        semantic channels: ``outdoor``'s cues)."""
        if mapper.target not in mapping.SEMANTIC:
            return targets
        channels = self._semantic(mapper)
        return np.zeros_like(targets) if channels is None else targets & ~channels[1]

    def _targets(self, mapper: mapping.EgoMapper) -> np.ndarray:
        """The target's mapped cells, less those near rejected goals or contradicted."""
        targets = mapper.grid[_TARGET].astype(bool) & ~self._contradicted(mapper)
        if self._rejected and targets.any():
            rows, cols = np.nonzero(targets)
            x, y = mapper.world(rows, cols)
            for point in self._rejected:
                far = np.hypot(x - point[0], y - point[1]) > REJECT_RADIUS
                targets[rows[~far], cols[~far]] = False
        return targets

    def _keep(self, mapper: mapping.EgoMapper, pose, targets: np.ndarray) -> bool:
        """Whether the current goal still stands (rejecting a target goal waited at too long)."""
        reached = math.hypot(self.goal[0] - pose[0], self.goal[1] - pose[1]) < REACHED
        if self.kind == "target":
            self._waited = self._waited + 1 if reached else 0
            if self._waited > TARGET_PATIENCE or self._age > PATIENCE:
                self._rejected.append(self.goal.copy())
                self._waited = 0
                return False
            return True
        if self.kind == "look":
            return self._age <= LOOK_STEPS and not targets.any()
        if reached or self._age > PATIENCE or targets.any():
            return False
        row, col, _ = mapper.cells(self.goal[0], self.goal[1])
        window = (slice(max(0, int(row) - 1), int(row) + 2), slice(max(0, int(col) - 1), int(col) + 2))
        return not mapper.grid[:len(mapping.CHANNELS)][(slice(None), *window)].any(0).all()

    def _set(self, mapper: mapping.EgoMapper, cost: np.ndarray, kind: str) -> None:
        if np.isfinite(cost).any():
            row, col = np.unravel_index(int(np.argmin(cost)), cost.shape)
            self.goal = np.array([float(v) for v in mapper.world(row, col)])
            self.kind = kind
            self._age = 0
            self._waited = 0

    def target_confirmed(self, mapper: mapping.EgoMapper) -> bool:
        """Whether the map shows target objects that are goals (neither contradicted nor rejected) of classes
        no other room type has: then the target is in sight beyond doubt."""
        return bool(self._confirmed(mapper, self._targets(mapper)).any())

    def _window(self, mapper: mapping.EgoMapper, pose) -> int:
        row, col = mapper.window_cell(pose, float(self.goal[0]), float(self.goal[1]))
        return row * mapping.WINDOW + col
