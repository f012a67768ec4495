"""The map-goal teacher: where on the agent's map the geodesic expert's path leads.

The labels of the map-goal sub-policy's network
(:mod:`leaps_mj.learning.train_goal`) and the goals of the ``oracle-map``
agent, which walks with the same :class:`leaps_mj.environment.map_navigation.GoalDriver`
as the learned sub-policy: the learned policy's ceiling, with perfect goals.
It reads the house's map (privileged), as the geodesic expert does.
:class:`ObservableTeacherGoals` (the ``oracle-map-observable`` agent) follows
the observable expert instead, whose choice of door rests only on what the
episode has shown; :class:`FurnitureTeacherGoals` and :class:`SensedTeacherGoals` (agents
``oracle-map-furniture``, ``oracle-map-sensed``) take away, in turn, what the agent cannot sense of
that: the type of a room seen only by its floor, and the doors it has never had in view.
:class:`GatedTeacherGoals` (``oracle-map-gated``) keeps the geodesic teacher's choice of door but
heads for a door only once the agent has mapped it.
"""

from __future__ import annotations

import numpy as np
import scipy.ndimage

from leaps_mj.environment import expert as expert_lib
from leaps_mj.environment import frontier, mapping, observable_expert
from leaps_mj.world import rooms

#: Metres down the geodesic path to the target at which the teacher's goal lies.
TEACHER_LOOKAHEAD = 3.0
#: Metres by which the teacher's goal zone is shrunk from its border (see :class:`TeacherGoals`).
TEACHER_INSET = 0.5
#: Range (metres) the potential labels are clipped to (:meth:`TeacherGoals.labels`): no window cell
#: is more than 6 m nearer the target than the agent; 8 m farther is as bad as a wall.
POTENTIAL_RANGE = (-6.0, 8.0)
#: Window cells the walk down a potential takes to its goal (:func:`potential_goal`): as far as the
#: teacher's goals lie down the path.
DESCENT = round(TEACHER_LOOKAHEAD / mapping.CELL)
#: Metres from a door's centre within which a mapped lintel counts as the door seen (:class:`SensedTeacherGoals`).
DOOR_SEEN = 0.5
#: Steps a :class:`GatedTeacherGoals` spends looking around on the spot in an episode before it follows frontiers.
GATED_LOOK = 12
#: The agent's own cell of the egocentric window (row-major): as a goal, the walk looks around on the spot.
AGENT_CELL = (mapping.WINDOW // 2) * mapping.WINDOW + mapping.WINDOW // 2
#: Offsets (metres) of the points of a window cell whose nearest free one gives its potential.
_SUBCELLS = tuple((dx, dy) for dx in (-mapping.CELL / 3, 0.0, mapping.CELL / 3)
                  for dy in (-mapping.CELL / 3, 0.0, mapping.CELL / 3))


def potential_goal(potential: np.ndarray) -> int:
    """The goal a potential over the egocentric window leads to, as a row-major window cell.

    The cell reached by :data:`DESCENT` steps from the agent's cell, each to the lowest of the
    8 neighbours while one is lower (:func:`leaps_mj.environment.expert.descend`). On the teacher's
    potential (:meth:`TeacherGoals.labels`) this is the way down the shortest path; on a network's
    prediction, the way towards where the target most likely lies.

    Args:
      potential: (WINDOW, WINDOW) or (WINDOW ** 2,) values, row-major over the window.
    """
    field = np.asarray(potential, np.float64).reshape(mapping.WINDOW, mapping.WINDOW)
    row, col = expert_lib.descend(field, mapping.WINDOW // 2, mapping.WINDOW // 2, DESCENT)
    return row * mapping.WINDOW + col


class TeacherGoals:
    """The teacher's goals, as cells of the egocentric map: the geodesic expert's path, looked further ahead.

    The goal is the point :data:`TEACHER_LOOKAHEAD` metres down the geodesic
    expert's steering field towards the target's zone (the viewing zone of
    its see-objects, or the rooms of ``outdoor`` and ``indoor``) shrunk by
    up to :data:`TEACHER_INSET` metres (as much as leaves any of it), so that the
    agent walks into the room rather than stopping on its threshold; inside
    that, the agent's own cell. Fields are cached per house and target.

    Args:
      env: The training environment.
      seed: Seed of the expert (its random moves are not used).
    """

    #: The expert whose steering fields the goals follow, and the options it is built with.
    expert_class = expert_lib.GeodesicExpert
    expert_options: dict = {}

    def __init__(self, env, seed: int = 0):
        self.env = env
        self.expert = self.expert_class(env, seed=seed, lookahead=TEACHER_LOOKAHEAD, **self.expert_options)
        self._fields: dict[tuple[str, str, tuple[int, ...]], tuple[np.ndarray, np.ndarray]] = {}
        # The last steering field, its zone's plain field, and each grid cell's nearest cell where that is finite.
        self._plain: tuple[np.ndarray, np.ndarray, np.ndarray] | None = None

    def _field(self, target: str, subset: tuple[int, ...] = ()) -> tuple[np.ndarray, np.ndarray]:
        """Steering field to the (shrunk) zone of ``target``, whose rooms the expert's ``field`` chooses
        (``subset`` names them for the cache; () for all)."""
        hm = self.env.task.house_model
        key = (hm.house.id, target, subset)
        if key not in self._fields:
            field, _, _ = self.expert.field(target, bool(rooms.SEE_OBJECTS.get(target)))
            zone = field == 0
            for iterations in range(max(1, round(TEACHER_INSET / hm.grid.cell)), 0, -1):
                inner = scipy.ndimage.binary_erosion(zone, iterations=iterations)
                if inner.any():
                    zone = inner
                    break
            self._fields[key] = self.expert.zone_field(zone)
        return self._fields[key]

    def steering(self) -> tuple[np.ndarray, np.ndarray]:
        """The steering field whose path the goal lies on at the current step."""
        return self._field(self.env.task.episode.target)

    def cell(self, mapper: mapping.EgoMapper, pose) -> int:
        """The goal at ``pose`` for the current episode, as a row-major index into the egocentric map.

        Call it every step: a teacher with a memory (:class:`ObservableTeacherGoals`) updates it here.
        """
        return self.labels(mapper, pose, potential=False)[0]

    def labels(self, mapper: mapping.EgoMapper, pose, potential: bool) -> tuple[int, np.ndarray | None]:
        """The goal cell of :meth:`cell` and, with ``potential``, the window's potential labels.

        The potential of a window cell is how many metres farther the steering field's zone lies
        from it than from the agent, on the house's grid (its nearest free part), clipped to
        :data:`POTENTIAL_RANGE` (cells with no free part — walls, furniture, outside the house — at
        its top), in :data:`leaps_mj.environment.mapping.CELL` units: (WINDOW, WINDOW) int8, oriented
        as the egocentric map. Descending it from the agent's cell follows the shortest path
        (:func:`potential_goal`). Unlike the goal cell, which is one choice a learner that has not
        seen the way cannot always read off its map, these labels
        score every cell, so a network regressing them learns how far the target is likely to be
        through each part of the map (the potential functions of PONI, Ramakrishnan et al., 2022).
        """
        field, nearest = self.steering()
        cell = self.goal_cell(field, nearest, mapper, pose)
        if not potential:
            return cell, None
        grid = self.env.task.house_model.grid
        if self._plain is None or self._plain[0] is not field:
            # The wide-clearance field leaves a door a corridor a window cell's centre can miss:
            # the potential is measured on the house's own grid, to the same zone.
            plain = grid.distance_from(field == 0)
            nearest = scipy.ndimage.distance_transform_edt(~np.isfinite(plain), return_distances=False,
                                                           return_indices=True)
            self._plain = (field, plain, nearest)
        _, plain, nearest = self._plain
        x, y = mapper.window_world(pose)
        metres = np.full(x.shape, np.inf)
        for dx, dy in _SUBCELLS:  # a window cell is as near as the nearest of its parts
            i = np.floor((x + dx - grid.origin[0]) / grid.cell).astype(np.int64)
            j = np.floor((y + dy - grid.origin[1]) / grid.cell).astype(np.int64)
            inside = (i >= 0) & (i < plain.shape[0]) & (j >= 0) & (j < plain.shape[1])
            metres[inside] = np.minimum(metres[inside], plain[i[inside], j[inside]])
        a, b = grid.to_cell(pose[:2])
        # The agent's cell, or (off the free grid) the nearest free one; 0 where no cell reaches the zone.
        here = plain[nearest[0, a, b], nearest[1, a, b]] if np.isfinite(plain).any() else 0.0
        low, high = POTENTIAL_RANGE
        relative = np.clip(np.nan_to_num(metres - here, posinf=high), low, high)
        return cell, np.round(relative / mapping.CELL).astype(np.int8)

    def goal_cell(self, field: np.ndarray, nearest: np.ndarray, mapper: mapping.EgoMapper, pose) -> int:
        """The window cell of the point :data:`TEACHER_LOOKAHEAD` metres down a steering field from ``pose``."""
        grid = self.env.task.house_model.grid
        i, j = grid.to_cell(pose[:2])
        # Off the field (too near a wall for the expert's clearance) the path starts at the field's nearest cell.
        start = pose[:2] if np.isfinite(field[i, j]) else grid.to_world((nearest[0, i, j], nearest[1, i, j]))
        point = self.expert.waypoint(field, nearest, start)
        if point is None:
            point = pose[:2]
        row, col = mapper.window_cell(pose, float(point[0]), float(point[1]))
        return row * mapping.WINDOW + col


class ObservableTeacherGoals(TeacherGoals):
    """The observable expert's path, looked :data:`TEACHER_LOOKAHEAD` metres ahead, as goals on the agent's map.

    :class:`TeacherGoals` leads straight to the door towards the target, which
    a learner that has not seen beyond it cannot know: its labels there are a
    guess to the learner. This teacher's goals follow
    :class:`leaps_mj.environment.observable_expert.ObservableExpert`: until a
    room of the target's type has been revealed, a point past the door of
    the room it explores next (unseen rooms first, nearest first); then the
    path to the revealed rooms' (shrunk) zone, as :class:`TeacherGoals`.

    Args:
      env: The training environment.
      seed: Seed of the expert (its random moves are not used).
    """

    expert_class = observable_expert.ObservableExpert

    def steering(self) -> tuple[np.ndarray, np.ndarray]:
        self.expert.observe()
        if not self.expert.target_revealed():
            walk = self.expert.walk(self.env.physics.agent_pose())
            if walk is not None:
                return walk
        target = self.env.task.episode.target
        return self._field(target, self.expert.target_rooms(target))


class FurnitureTeacherGoals(ObservableTeacherGoals):
    """:class:`ObservableTeacherGoals` with rooms revealed by their furniture only
    (``ObservableExpert(reveal="furniture")``): the agent's segmentation shows one floor class and
    one ceiling class, so a glimpse of a room's floor tells the learner nothing of its type."""

    expert_options = {"reveal": "furniture"}


class SensedTeacherGoals(FurnitureTeacherGoals):
    """:class:`FurnitureTeacherGoals` exploring only the doors the agent has mapped.

    The observable expert walks to the doors of the house's plan, those the agent has never had in
    view too. This teacher explores a door only once the agent's own map
    (:class:`leaps_mj.environment.mapping.EgoMapper`) shows a door lintel within
    :data:`DOOR_SEEN` metres of its centre; with none left to explore and no room of the target's
    type revealed, its goal is the agent's own cell, where the walk looks around
    (:class:`leaps_mj.environment.map_navigation.GoalDriver`). What it still reads off the plan is
    which room the agent stands in and where the rooms beyond mapped doors lie.
    """

    def labels(self, mapper: mapping.EgoMapper, pose, potential: bool) -> tuple[int, np.ndarray | None]:
        self.expert.door_filter = lambda centre: door_mapped(mapper, centre)
        cell, labels = super().labels(mapper, pose, potential)
        if not self.expert.target_revealed() and self.expert.goal is None:
            cell = AGENT_CELL
        return cell, labels


def door_mapped(mapper: mapping.EgoMapper, centre) -> bool:
    """Whether the map's ``door`` channel has a cell within :data:`DOOR_SEEN` metres (in cells) of a
    door's centre (x, y)."""
    rows, cols, inside = mapper.cells(centre[0], centre[1])
    if not bool(inside):
        return False
    reach = round(DOOR_SEEN / mapping.CELL)
    row, col = int(rows), int(cols)
    door = mapper.grid[mapping.CHANNELS.index("door")]
    return bool(door[max(0, row - reach):row + reach + 1, max(0, col - reach):col + reach + 1].any())


class GatedTeacherGoals(TeacherGoals):
    """The geodesic teacher's goals, gated by the doors the agent has mapped.

    :class:`TeacherGoals` heads for the door towards the target even where the agent has never had
    it in view, a goal in unmapped space that a learner cannot read off its map.
    This teacher keeps that choice of door (the privileged part: which of the doors it has seen
    leads on) but takes it only once the door is on the agent's map (:func:`door_mapped`); until
    then it looks around on the spot (its goal the agent's own cell, for up to :data:`GATED_LOOK`
    steps an episode) and then follows frontiers (:class:`leaps_mj.environment.frontier.FrontierGoals`).
    Once a room of the target's type has been revealed by its furniture (or stood in:
    :class:`leaps_mj.environment.observable_expert.ObservableExpert` with ``reveal="furniture"``) its
    goals are the geodesic teacher's throughout.

    The door it waits for is the one of the room the agent stands in where the steering field is
    lowest: where the shortest path to the target leaves the room.

    Args:
      env: The training environment.
      seed: Seed of the experts (their random moves are not used).
    """

    def __init__(self, env, seed: int = 0):
        super().__init__(env, seed)
        self.memory = observable_expert.ObservableExpert(env, seed=seed, reveal="furniture")
        self._episode = None
        self._looked = 0
        self._frontier = frontier.FrontierGoals()

    def labels(self, mapper: mapping.EgoMapper, pose, potential: bool) -> tuple[int, np.ndarray | None]:
        task = self.env.task
        if self._episode is not task.episode:  # a new episode (the trainer does not announce one)
            self._episode, self._looked = task.episode, 0
            self._frontier.reset()
        self.memory.observe()
        cell, labels = super().labels(mapper, pose, potential)
        door = self.door_out(pose)
        if self.memory.target_revealed() or door is None or door_mapped(mapper, door.center):
            return cell, labels
        if self._looked < GATED_LOOK:
            self._looked += 1
            return AGENT_CELL, labels
        return self._frontier.cell(_MapView(mapper, pose)), labels

    def door_out(self, pose):
        """The door of the room at ``pose`` where the steering field is lowest (None outside any room
        or in a room without doors)."""
        hm = self.env.task.house_model
        room = hm.room_at(pose[:2])
        field, nearest = self.steering()
        best, out = np.inf, None
        for door in hm.house.doors:
            if room not in door.rooms:
                continue
            i, j = hm.grid.to_cell(door.center)
            value = field[i, j] if np.isfinite(field[i, j]) else field[nearest[0, i, j], nearest[1, i, j]]
            if value < best:
                best, out = value, door
        return out


class _MapView:
    """The two attributes of a driver that :meth:`leaps_mj.environment.frontier.FrontierGoals.cell` reads."""

    def __init__(self, mapper: mapping.EgoMapper, pose):
        self.mapper, self.pose = mapper, pose
