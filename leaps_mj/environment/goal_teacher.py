"""The map-goal teacher: where on the agent's map the geodesic expert's path leads.

The labels of the map-goal sub-policy's network
(:mod:`leaps_mj.learning.train_goal`) and the goals of the ``oracle-map``
agent, which walks with the same :class:`leaps_mj.environment.map_navigation.GoalDriver`
as the learned sub-policy: the learned policy's ceiling, with perfect goals.
It reads the house's map (privileged), as the geodesic expert does.
:class:`ObservableTeacherGoals` (the ``oracle-map-observable`` agent) follows
the observable expert instead, whose choice of door rests only on what the
episode has shown.
"""

from __future__ import annotations

import numpy as np
import scipy.ndimage

from leaps_mj.environment import expert as expert_lib
from leaps_mj.environment import mapping, observable_expert
from leaps_mj.world import rooms

#: Metres down the geodesic path to the target at which the teacher's goal lies.
TEACHER_LOOKAHEAD = 3.0
#: Metres by which the teacher's goal zone is shrunk from its border (see :class:`TeacherGoals`).
TEACHER_INSET = 0.5


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

    #: The expert whose steering fields the goals follow.
    expert_class = expert_lib.GeodesicExpert

    def __init__(self, env, seed: int = 0):
        self.env = env
        self.expert = self.expert_class(env, seed=seed, lookahead=TEACHER_LOOKAHEAD)
        self._fields: dict[tuple[str, str, tuple[int, ...]], tuple[np.ndarray, np.ndarray]] = {}

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
        return self.goal_cell(*self.steering(), mapper, pose)

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
