"""The observable expert: a teacher whose choices rest only on what the agent has observed.

The geodesic expert (:class:`leaps_mj.environment.expert.GeodesicExpert`)
reads the map: from a room with several doors it walks straight to the one
that leads to the target's room type, a choice a learner seeing only its own
frames cannot know, so imitation of it plateaus. This teacher still walks
with the map (shortest paths, clearance), but *where* it goes depends only on
the episode so far:

* **Memory.** Every step it notes the room it stands in (*visited*) and the
  rooms whose floor, ceiling or furniture cover at least
  :data:`REVEAL_FRACTION` of the frame (*revealed*; visited rooms are
  revealed too). The learner's segmentation shows a room's type only through
  its furniture (floors and ceilings are one class each), so a room glimpsed
  by its floor alone is known here a little earlier than a learner could tell.
* **Target in sight.** Once a room of the target's type (for ``indoor``:
  untyped indoor space) is revealed, it acts exactly as the geodesic expert
  does, with the goal restricted to the revealed rooms of that type: the
  viewing zone near the see-objects, facing them, staying while the see
  test holds.
* **Explore.** Otherwise it walks through a door of a visited room into a
  room not yet visited, to a point :data:`BEYOND_DOOR` metres past the door,
  and then chooses again. Doors to rooms not yet seen go first (a room seen
  and not of the target's type needs no visit to know that), nearest first
  (geodesic from the agent); then doors to seen rooms, those whose type is
  most often adjacent to the target's in real homes first (the release's
  prior, :func:`leaps_mj.world.rooms.reference_prior`: the dining room when
  looking for the kitchen); ties go to the lower door index. A walk towards
  an unseen room is dropped when that room comes into view (unseen rooms
  then go first again). A door once passed, or given up after
  :data:`DOOR_PATIENCE` steps, is done, so it does not loop. With nothing
  left to explore it falls back on the geodesic expert.

Two variants take away what the agent cannot sense (agents ``oracle-map-furniture`` and
``oracle-map-sensed`` of the hop benchmark; session 15 of docs/training.md): ``reveal="furniture"``
counts only the room's furniture towards :data:`REVEAL_FRACTION` (the learner's segmentation has one
floor class and one ceiling class, so only furniture tells it a room's type), and
:attr:`ObservableExpert.door_filter` restricts the doors it explores to those the agent has seen
(:class:`leaps_mj.environment.goal_teacher.SensedTeacherGoals` sets it from the agent's own map).

The memory is per episode: a new episode is detected by
:meth:`leaps_mj.environment.expert.GeodesicExpert.new_episode`, since the
sub-policy trainer calls :meth:`ObservableExpert.act` every step without
calling ``reset``.
"""

from __future__ import annotations

import numpy as np

from leaps_mj.environment import expert
from leaps_mj.world import rooms

#: Share of the frame a room's pixels must cover for the room to count as revealed.
REVEAL_FRACTION = 0.01
#: Metres past a door's centre, into the room beyond, where an exploration walk ends.
BEYOND_DOOR = 1.0
#: Metres around that point (within the room) that count as arrived.
ARRIVE_RADIUS = 0.5
#: Steps after which an exploration walk to a door is given up (the door is then done).
DOOR_PATIENCE = 50
#: What reveals a room (``ObservableExpert``'s ``reveal``): any of its pixels, or its furniture's only.
REVEALS = ("room", "furniture")
#: Indices of the class and room-id tables in ``RoomNavEnvironment.segment_luts``.
_CLASS_LUT, _ROOM_LUT = 0, 3
_FURNITURE = np.array([rooms.seg_class_index(c) for c in rooms.FURNITURE_CLASSES])


class ObservableExpert(expert.GeodesicExpert):
    """A teacher acting on the rooms seen and the doors passed so far (see the module docstring).

    Args:
      env: the :class:`leaps_mj.environment.roomnav.RoomNavEnvironment` whose episodes it solves.
      seed: seed of the small random moves it makes when blocked.
      lookahead: metres of path ahead used as the steering waypoint.
      reveal: what reveals a room (:data:`REVEALS`): ``room``, any pixel of it (floor, ceiling, walls,
        furniture); ``furniture``, its furniture's pixels only.

    Attributes:
      visited: ids of the rooms the agent has stood in this episode.
      revealed: ids of the rooms seen (or visited) this episode.
      passed: indices (in ``house.doors``) of the doors done this episode.
      goal: (door index, room id beyond it) of the current exploration walk, or None.
      door_filter: None (every door of the plan may be explored), or a function of a door's centre
        (x, y) saying whether it may.

    Raises:
      ValueError: for an unknown ``reveal``.
    """

    def __init__(self, env, seed: int = 0, lookahead: float = 0.6, reveal: str = "room"):
        if reveal not in REVEALS:
            raise ValueError(f"reveal {reveal!r}: expected one of {list(REVEALS)}")
        super().__init__(env, seed=seed, lookahead=lookahead)
        self.reveal = reveal
        self.door_filter = None
        # Fields of the current house only (door walks, subsets of target rooms): bounded memory.
        self._house_id: str | None = None
        self._house_fields: dict[tuple, tuple] = {}
        self.reset()

    def reset(self) -> None:
        """Forgets the episode's memory (also done by itself when a new episode starts)."""
        self.visited: set[int] = set()
        self.revealed: set[int] = set()
        self.passed: set[int] = set()
        self.goal: tuple[int, int] | None = None
        self._goal_step = 0  # when the current walk began
        self._goal_unseen = False  # whether its room was unseen then

    def observe(self) -> None:
        """Adds the current step to the memory, starting afresh at a new episode."""
        task = self.env.task
        if self.new_episode():
            self.reset()
        hm = task.house_model
        room = hm.room_at(self.env.physics.agent_pose()[:2])
        if room >= 0:
            self.visited.add(room)
        ids = self.env.segment_luts[_ROOM_LUT].take(task.segments).ravel() + 1
        if self.reveal == "furniture":
            ids[~np.isin(self.env.segment_luts[_CLASS_LUT].take(task.segments).ravel(), _FURNITURE)] = 0
        counts = np.bincount(ids, minlength=len(hm.house.rooms) + 1)[1:]
        self.revealed.update(np.flatnonzero(counts >= REVEAL_FRACTION * ids.size).tolist())
        self.revealed |= self.visited

    def act(self, timestep=None) -> int:
        """The teacher's action for the environment's current state (updates the memory first)."""
        del timestep
        self.observe()
        task = self.env.task
        if task.sees():
            return expert.STAY
        if not self.target_revealed():
            pose = self.env.physics.agent_pose()
            walk = self.walk(pose)
            if walk is not None:
                return self.follow(*walk, pose)
        return super().act()

    def target_revealed(self) -> bool:
        """Whether a room of the episode's target type has been revealed (then the walk is the geodesic expert's)."""
        task = self.env.task
        return any(r.type == task.episode.target and r.id in self.revealed for r in task.house_model.house.rooms)

    def target_rooms(self, target: str) -> tuple[int, ...]:
        """The rooms of type ``target`` its finish steers to: the revealed ones, or () meaning all of them
        (none revealed, or all)."""
        ids = [r.id for r in self.env.task.house_model.house.rooms if r.type == target]
        seen = tuple(i for i in ids if i in self.revealed)
        return seen if len(seen) < len(ids) else ()

    def field(self, target: str, view: bool) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """The geodesic expert's field towards the *revealed* rooms of type ``target``.

        With none of them revealed (nothing left to explore) or all of them,
        it is the geodesic expert's own field.
        """
        seen = self.target_rooms(target)
        if not seen:
            return super().field(target, view)
        return self._cached(("target", target, view, seen), lambda: self.target_field(target, view, seen))

    def _cached(self, key: tuple, make):
        """A field of the current house, computed once (the cache is emptied when the house changes)."""
        house_id = self.env.task.house_model.house.id
        if house_id != self._house_id:
            self._house_id, self._house_fields = house_id, {}
        if key not in self._house_fields:
            self._house_fields[key] = make()
        return self._house_fields[key]

    def walk(self, pose) -> tuple[np.ndarray, np.ndarray] | None:
        """Steering field of the exploration walk at ``pose`` (choosing a new door where needed, dropping a
        walk that arrived or ran out of patience); None when all is explored.

        Call it once a step (after :meth:`observe`): a walk's patience counts the task's steps.
        """
        task = self.env.task
        if self.goal is not None and self._goal_unseen and self.goal[1] in self.revealed:
            self.goal = None  # its room came into view: doors to rooms still unseen go first now
        while True:
            if self.goal is None:
                self.goal = self._next_door(pose)
                if self.goal is None:
                    return None
                self._goal_step = task.steps
                self._goal_unseen = self.goal[1] not in self.revealed
            field, nearest = self._door_field(*self.goal)
            if self.waypoint(field, nearest, pose[:2]) is not None and task.steps - self._goal_step < DOOR_PATIENCE:
                return field, nearest
            self.passed.add(self.goal[0])  # arrived, or given up
            self.goal = None

    def _next_door(self, pose) -> tuple[int, int] | None:
        """(door index, room beyond) of the next door to explore, or None when there is none left.

        Candidates are the doors not yet done from a visited room to an
        unvisited one that the agent can reach (and that :attr:`door_filter` allows). Doors to rooms not yet seen
        come first, nearest first; then doors to seen rooms, those of the
        room types most often adjacent to the target's
        (:func:`leaps_mj.world.rooms.reference_prior`) first, then nearest;
        remaining ties go to the lower door index.
        """
        hm = self.env.task.house_model
        i, j = hm.grid.to_cell(pose[:2])
        prior = rooms.reference_prior()[rooms.room_index(self.env.task.episode.target)]
        types = {r.id: r.type for r in hm.house.rooms}
        best = None
        for index, door in enumerate(hm.house.doors):
            a, b = door.rooms
            if index in self.passed or (a in self.visited) == (b in self.visited):
                continue
            room = b if a in self.visited else a
            if self.door_filter is not None and not self.door_filter(door.center):
                continue
            field, nearest = self._door_field(index, room)
            metres = field[nearest[0, i, j], nearest[1, i, j]]
            if not np.isfinite(metres):
                continue
            seen = room in self.revealed
            key = (seen, -prior[rooms.room_index(types[room])] if seen else 0.0, metres, index)
            if best is None or key < best[0]:
                best = (key, index, room)
        return None if best is None else best[1:]

    def _door_field(self, index: int, room: int) -> tuple[np.ndarray, np.ndarray]:
        """Steering field to the free cells of ``room`` within :data:`ARRIVE_RADIUS` of the point
        :data:`BEYOND_DOOR` metres past door ``index`` (or, where that point is not free floor of
        the room, of its free cells nearest to it)."""

        def make():
            hm = self.env.task.house_model
            grid, door = hm.grid, hm.house.doors[index]
            normal = np.array([0.0, 1.0] if door.axis == "x" else [1.0, 0.0])  # across the wall
            centre = np.asarray(door.center, dtype=float)
            if hm.room_at(centre + 0.5 * normal) != room:
                normal = -normal
            point = centre + BEYOND_DOOR * normal
            cells = (grid.room_id == room) & grid.free
            xs, ys = grid.cell_centers()
            gap = np.where(cells, np.hypot(xs - point[0], ys - point[1]), np.inf)
            return self.zone_field(cells & (gap <= gap.min() + ARRIVE_RADIUS))  # empty: unreachable, skipped

        return self._cached(("door", index, room), make)
