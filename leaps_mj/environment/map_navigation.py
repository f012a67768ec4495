"""Walking to a point on the agent's own map: shortest paths over the cells it has not seen blocked.

:class:`MapNavigator` is the low-level half of the map-goal sub-policy
(:mod:`leaps_mj.learning.goal_policy`): a learned network picks *where* to go
on the egocentric map, and this deterministic controller gets there with the
9 discrete actions. It plans on :class:`leaps_mj.environment.mapping.EgoMapper`'s
``blocked`` layer, widened by the agent's radius, and treats unseen cells as
free (the optimistic assumption of frontier exploration); its steering is the
geodesic expert's (face the point ``lookahead`` down the path, then move), the
point pulled nearer where the straight way to it would graze a mapped obstacle
(steering at a point 3 cells on cut the path's corners into furniture and door
frames: 27–35 collisions in 60 steps in the wedged runs of session 12), so it
reads nothing the agent does not sense: its own map, pose and collision flag.
:class:`GoalDriver` wraps a map, a navigator and the current goal into one
run's controller, the part shared by the learned map-goal sub-policy, its
trainer and the ``oracle-map`` agent (the same driver with the teacher's goals).
"""

from __future__ import annotations

import math

import numpy as np
import scipy.ndimage

from leaps_mj.environment import expert, mapping, render, roomnav
from leaps_mj.world import rooms

#: Steps between two goal choices of a :class:`GoalDriver` (it walks to the last goal in between).
REPLAN = 4
#: The rotations among the 9 actions (a :class:`GoalDriver` that commits to turns does not choose mid-turn).
TURNS = frozenset({expert.LEFT, expert.RIGHT, expert.SMALL_LEFT, expert.SMALL_RIGHT})
#: Share of the frame the target's objects must fill for a :class:`GoalDriver` to stop and look (the see test's).
SEE_FRACTION = roomnav.EnvConfig.success_fraction

#: Cells around a blocked cell that the planner keeps off (the agent's radius, 0.2 m, and a margin).
CLEARANCE = 1
#: Cells of path ahead of the agent it steers towards.
LOOKAHEAD = 3
#: Extra cells around the agent and the goal that a plan may use.
MARGIN = 12
#: Half-width (metres) of the agent's body swept along a shortcut (:meth:`MapNavigator.waypoint`; its radius is 0.2).
BODY = 0.15
#: Metres from the goal within which the agent has arrived.
ARRIVED = 0.35
_STEPS = ((-1, 0, 1.0), (1, 0, 1.0), (0, -1, 1.0), (0, 1, 1.0),
          (-1, -1, math.sqrt(2)), (-1, 1, math.sqrt(2)), (1, -1, math.sqrt(2)), (1, 1, math.sqrt(2)))
_NEIGHBOURS = tuple((di, dj) for di, dj, _length in _STEPS)


def path_distances(free: np.ndarray, goal: tuple[int, int]) -> np.ndarray:
    """Shortest 8-connected path lengths (in cells) to ``goal`` over the ``free`` cells.

    A wavefront: every sweep lowers each free cell to its neighbours' distance
    plus the step's length, until nothing changes. The goal's own cell counts
    as free.

    Args:
      free: (R, C) bool.
      goal: (row, column) of the goal cell.

    Returns:
      (R, C) float, ``inf`` where the goal cannot be reached.
    """
    dist = np.full(free.shape, np.inf)
    dist[goal] = 0.0
    free = free.copy()
    free[goal] = True
    padded = np.full((free.shape[0] + 2, free.shape[1] + 2), np.inf)
    for _ in range(free.size):
        padded[1:-1, 1:-1] = dist
        best = dist.copy()
        for di, dj, length in _STEPS:
            np.minimum(best, padded[1 + di:1 + di + free.shape[0], 1 + dj:1 + dj + free.shape[1]] + length, out=best)
        best[~free] = np.inf
        if np.array_equal(best, dist):
            break
        dist = best
    return dist


class MapNavigator:
    """Steers the agent to world points over the map it has built so far.

    Args:
      mapper: The run's map (updated by the caller before each :meth:`act`).
      seed: Seed of the random unsticking moves after a collision.
    """

    def __init__(self, mapper: mapping.EgoMapper, seed: int = 0):
        self.mapper = mapper
        self.rng = np.random.default_rng(seed)

    def reset(self, seed: int | None = None) -> None:
        """A new run (optionally reseeding the unsticking moves)."""
        if seed is not None:
            self.rng = np.random.default_rng(seed)

    def bumped(self, pose) -> None:
        """Records a collision: the cell just ahead of ``pose`` is blocked."""
        x, y, yaw = (float(v) for v in pose)
        self.mapper.block(x + 0.35 * math.cos(yaw), y + 0.35 * math.sin(yaw))

    def waypoint(self, pose, goal_xy) -> np.ndarray | None:
        """The farthest of the next :data:`LOOKAHEAD` cells of the shortest path from ``pose`` to ``goal_xy``
        that the agent can walk to straight without touching a mapped blocked cell (else the next cell).

        The path keeps :data:`CLEARANCE` cells off blocked cells where it can,
        and may touch them where it cannot; where the map knows no path at all
        (the agent hemmed in by what it mapped), the goal itself.

        Returns:
          (x, y), or None when the agent is within :data:`ARRIVED` metres of the goal.
        """
        if math.hypot(goal_xy[0] - pose[0], goal_xy[1] - pose[1]) < ARRIVED:
            return None
        m = self.mapper
        (ar, gr), (ac, gc), _ = m.cells([pose[0], goal_xy[0]], [pose[1], goal_xy[1]])
        ar, ac, gr, gc = (int(np.clip(v, 0, mapping.GRID - 1)) for v in (ar, ac, gr, gc))
        if (ar, ac) == (gr, gc):
            return np.asarray(goal_xy[:2], np.float64)
        r0, c0 = max(0, min(ar, gr) - MARGIN), max(0, min(ac, gc) - MARGIN)
        r1, c1 = min(mapping.GRID, max(ar, gr) + MARGIN + 1), min(mapping.GRID, max(ac, gc) + MARGIN + 1)
        i, j = ar - r0, ac - c0
        for clearance in (CLEARANCE, 0):
            blocked = m.blocked[r0:r1, c0:c1]
            free = ~scipy.ndimage.binary_dilation(blocked, iterations=clearance) if clearance else ~blocked
            free[i, j] = True  # the agent's own cell, even when a wall was mapped into it
            dist = path_distances(free, (gr - r0, gc - c0))
            if np.isfinite(dist[i, j]):
                break
        else:
            return np.asarray(goal_xy[:2], np.float64)
        path = []
        for _ in range(LOOKAHEAD):
            step = expert.descend(dist, i, j, 1, _NEIGHBOURS)
            if step == (i, j):
                break
            i, j = step
            path.append(m.world(i + r0, j + c0))
        if not path:
            return np.asarray(goal_xy[:2], np.float64)
        reachable = [p for p in path[1:] if self._clear(pose, p)]
        x, y = reachable[-1] if reachable else path[0]
        return np.array([float(x), float(y)])

    def _clear(self, pose, point) -> bool:
        """Whether the agent's body (:data:`BODY` metres each side of its centre line) passes no blocked
        cell on the straight way from ``pose`` to ``point``: steering cuts the planned path's corners
        only where the map shows the shortcut free."""
        dx, dy = point[0] - pose[0], point[1] - pose[1]
        length = math.hypot(dx, dy)
        t = np.linspace(0.0, 1.0, max(2, int(math.ceil(length / (mapping.CELL / 4))) + 1))[1:]
        nx, ny = -dy / max(length, 1e-9), dx / max(length, 1e-9)
        for side in (-BODY, 0.0, BODY):
            rows, cols, inside = self.mapper.cells(pose[0] + t * dx + side * nx, pose[1] + t * dy + side * ny)
            if np.any(self.mapper.blocked[rows[inside], cols[inside]]):
                return False
        return True

    def act(self, pose, goal_xy, collided: bool) -> int | None:
        """The action towards ``goal_xy`` from ``pose``; None at the goal.

        After a collision it marks the blocked cell and, half of the time,
        makes a random unsticking move as the geodesic expert does.
        """
        if collided:
            self.bumped(pose)
            action = expert.unstick(self.rng)
            if action is not None:
                return action
        wp = self.waypoint(pose, goal_xy)
        return None if wp is None else expert.steer(pose, wp)


class GoalDriver:
    """One run's map, planner and goal: turns observations and chosen goals into actions.

    The sub-policy gives it goals from the network; the trainer from the
    network or from the teacher. Call :meth:`observe` with each step's
    observation, then :meth:`set_goal` when :meth:`needs_goal`, then :meth:`act`.

    Args:
      target: The graph node of the run.
      width, height: Resolution of the frames it is given.
      seed: Seed of the planner's unsticking moves.
      commit_turns: Choose a new goal only once at least :data:`REPLAN` steps
        went by *and* the last action was not a rotation, so a turn towards
        a goal is finished before another goal is chosen; otherwise every
        :data:`REPLAN` steps. Choosing mid-turn lets a learned goal flip
        between two doors as the view turns: the agent then turns left and
        right on the spot (session 8, docs/training.md). Turns made at the
        goal (looking around, or facing the target) do not hold the choice
        back: a driver that commits would otherwise turn there for good.
      context: :meth:`observe` also returns the coarse 16 m window
        (:meth:`leaps_mj.environment.mapping.EgoMapper.context`) below the fine one.
      cues: The map marks the target's cues (:data:`leaps_mj.environment.mapping.CUES`).
      semantic: The map marks every room type's see-objects (:data:`leaps_mj.environment.mapping.SEMANTIC`).
    """

    def __init__(self, target: str, width: int, height: int, seed: int = 0, commit_turns: bool = True,
                 context: bool = False, cues: bool = False, semantic: bool = False):
        self.target = target
        self.commit_turns = commit_turns
        self.context = context
        self.node = rooms.GRAPH_NODES.index(target)
        self.mapper = mapping.EgoMapper(target, width, height, cues, semantic)
        self.navigator = MapNavigator(self.mapper, seed)
        see = [rooms.seg_class_index(c) for c in rooms.SEE_OBJECTS.get(target, ())]
        self._see = np.zeros(rooms.NUM_SEG_CLASSES, bool)
        self._see[see] = True
        self.reset()

    def reset(self, seed: int | None = None) -> None:
        """A new run: empty map, no goal."""
        self.mapper.reset()
        self.navigator.reset(seed)
        self.goal: np.ndarray | None = None
        self.steps = 0
        self._since_goal = 0
        self._last_action: int | None = None
        self._arrived = False  # whether the last action was taken at the goal (looking, not walking)
        self.pose = np.zeros(3)
        self._collided = False
        self._fraction = 0.0

    def observe(self, observation) -> np.ndarray:
        """Adds the step's frame to the map; returns the egocentric map (C, WINDOW, WINDOW), with
        ``context`` the coarse window's C channels after the fine window's (2C, WINDOW, WINDOW).

        Frames of an integer multiple of the driver's resolution are subsampled to it
        (:func:`leaps_mj.environment.render.subsample`).

        Raises:
          ValueError: for frames of another size.
        """
        width, height = self.mapper.width, self.mapper.height
        seg = render.subsample(observation["segmentation"], width, height)
        self.pose = np.asarray(observation["pose"], np.float64)
        self._collided = bool(observation["collision"]) and self.steps > 0
        self._fraction = float(self._see[seg].mean())
        window = self.mapper.update(seg, render.subsample(observation["depth"], width, height), self.pose)
        return np.concatenate([window, self.mapper.context(self.pose)]) if self.context else window

    def needs_goal(self) -> bool:
        """Whether this step chooses a new goal: the first step, then after :data:`REPLAN` steps (and,
        with ``commit_turns``, not in the middle of a turn)."""
        if self.goal is None:
            return True
        mid_turn = self._last_action in TURNS and not self._arrived
        return self._since_goal >= REPLAN and not (self.commit_turns and mid_turn)

    def set_goal(self, cell: int) -> None:
        """Heads for a cell of the egocentric map (row-major index into the window) around the current pose."""
        row, col = divmod(int(cell), mapping.WINDOW)
        x, y = self.mapper.window_world(self.pose)
        self.goal = np.array([x[row, col], y[row, col]])
        self._since_goal = 0

    def act(self) -> int:
        """The action of this step: walk to the goal; there, face the target's nearest mapped object."""
        self.steps += 1
        self._since_goal += 1
        self._last_action = self._action()
        return self._last_action

    def _action(self) -> int:
        action = self.navigator.act(self.pose, self.goal, self._collided) if self.goal is not None else None
        self._arrived = action is None
        if action is not None:
            return action
        seen = np.argwhere(self.mapper.grid[mapping.CHANNELS.index("target")])
        if not len(seen):
            return expert.LEFT  # nothing of the target mapped here: look around
        x, y = self.mapper.world(seen[:, 0], seen[:, 1])
        distance = np.hypot(x - self.pose[0], y - self.pose[1])
        k = int(np.argmin(distance))
        err = math.remainder(math.atan2(y[k] - self.pose[1], x[k] - self.pose[0]) - self.pose[2], 2 * math.pi)
        if abs(err) > math.radians(10):
            return expert.turn_action(err)
        if self._fraction >= SEE_FRACTION:
            return expert.STAY
        return expert.SMALL_FORWARD if distance[k] > 1.0 else expert.STAY
