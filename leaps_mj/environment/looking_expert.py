"""The looking expert: a teacher that looks around a room before it walks out of it.

From a room next to the target's, the geodesic expert
(:class:`leaps_mj.environment.expert.GeodesicExpert`) walks straight to the
door that leads there, a choice the frames often cannot show: on the one-door
hop episodes the target's see-objects come into view somewhere in a full turn
at the start in only about half of the episodes. Imitating those choices, a
learner turns left and right at random where it cannot tell, and rarely
completes the look around that would show it the target.

This teacher makes the look around explicit, with a stopping rule the learner
can see:

* **Target seen.** Once a see-object of the target's type has been in the
  frame this episode (the pixels the see test counts), or the agent stands in
  a room of that type, it acts as the geodesic expert.
* **Look around.** Otherwise, until the camera has covered the full circle
  from inside the room the agent stands in, it turns left (30°).
* **Walk on.** With the room looked around and nothing seen, it acts as the
  geodesic expert (which leads through the right door; the next room is
  looked around in turn).

Targets without see-objects (``outdoor``, ``indoor``: being there is the
test) get the geodesic expert's actions throughout. Coverage is kept per
room, in bins of :data:`BIN_DEGREES`, from the headings the agent faced
while standing in it (doorways, outside every room, count for the last room
it stood in). The memory is per episode
(:meth:`leaps_mj.environment.expert.GeodesicExpert.new_episode`).
"""

from __future__ import annotations

import math

import numpy as np

from leaps_mj.environment import expert
from leaps_mj.world import rooms

#: Width (degrees) of the heading bins of a room's coverage.
BIN_DEGREES = 10


class LookingGeodesicExpert(expert.GeodesicExpert):
    """The geodesic expert, looking around each room until the target is seen (see the module docstring).

    Args:
      env: the :class:`leaps_mj.environment.roomnav.RoomNavEnvironment` whose episodes it solves.
      seed: seed of the small random moves it makes when blocked.
      lookahead: metres of path ahead used as the steering waypoint.

    Attributes:
      seen: whether a see-object of the target's type has been in view this episode.
      covered: room id -> boolean heading bins the camera has covered from inside that room.
      room: the room the agent last stood in (-1 before any).
    """

    def __init__(self, env, seed: int = 0, lookahead: float = 0.6):
        super().__init__(env, seed=seed, lookahead=lookahead)
        self._bins = 360 // BIN_DEGREES
        self._centres = np.radians((np.arange(self._bins) + 0.5) * BIN_DEGREES)
        self.reset()

    def reset(self) -> None:
        """Forgets the episode's memory (also done by itself when a new episode starts)."""
        self.seen = False
        self.covered: dict[int, np.ndarray] = {}
        self.room = -1

    def observe(self) -> None:
        """Adds the current frame to the memory, starting afresh at a new episode."""
        if self.new_episode():
            self.reset()
        task = self.env.task
        x, y, yaw = self.env.physics.agent_pose().tolist()
        room = task.house_model.room_at((x, y))
        if room >= 0:
            self.room = room
        self.seen = self.seen or task.target_fraction > 0
        if self.room >= 0:
            bins = self.covered.setdefault(self.room, np.zeros(self._bins, dtype=bool))
            off = np.abs(np.remainder(self._centres - yaw + math.pi, 2 * math.pi) - math.pi)
            bins |= off <= expert.half_view(self.env)

    def looked_around(self) -> bool:
        """Whether the camera has covered the full circle from inside the current room."""
        return self.room >= 0 and bool(self.covered[self.room].all())

    def act(self, timestep=None) -> int:
        """The teacher's action for the environment's current state (updates the memory first)."""
        del timestep
        self.observe()
        task = self.env.task
        if (rooms.SEE_OBJECTS.get(task.episode.target) and not (self.seen or task.in_target)
                and not self.looked_around()):
            return expert.LEFT
        return super().act()
