"""Agents for RoomNav: random, pure sub-policy, LEAPS, the two experts and the local-expert sub-policy.

The learned baselines ("aug", "controller") live in :mod:`leaps_mj.learning.baselines`;
:func:`leaps_mj.evaluation.registry.make_agent` builds any of them by name.

Two small interfaces are the contract between agents, sub-policies, the
episode loop (:func:`leaps_mj.environment.episodes.run_episode`) and the episode recorder:

* A **sub-policy** μ(target) is any object with ``reset(target: str)``
  (start a new run towards a room of that type; resets recurrent state) and
  ``act(timestep) -> int``. The learned CNN+LSTM policies and the
  :class:`LocalExpertPolicy` below both implement it.
* An **agent** has a ``name``, ``reset(target)`` at the start of an episode,
  ``step(timestep) -> int`` and ``info() -> dict`` with the keys
  ``"subtarget"`` (room type or None), ``"plan"`` (node names, ``[]`` when the
  agent does not plan) and ``"belief"`` (the 9x9 posterior, or None).

:class:`LeapsAgent` reads only ``timestep.observation["semantic"]`` and
``["target"]`` itself; everything it sees of pixels goes through its
sub-policy. Agents that need privileged state (the oracle, the local expert)
take the environment in their constructor.
"""

from __future__ import annotations

import dataclasses
import os
import pathlib
from typing import Protocol, runtime_checkable

import numpy as np
import scipy.ndimage

from leaps_mj.environment import expert, frontier, goal_teacher, looking_expert, map_navigation, observable_expert
from leaps_mj.planning import semantic
from leaps_mj.world import rooms

#: Shipped priors, by name: ``leaps_mj/data/prior_<name>.json``.
#: The prior the LEAPS agent uses unless told otherwise.
DEFAULT_PRIOR = "cpu"
#: The shipped prior the commands give LEAPS with each kind of sub-policy: the same learned connectivity, with
#: the observation noise tuned on the validation episodes for that sub-policy (``python -m leaps_mj.train
#: obs-noise --subpolicy local|learned``): ψ_obs reflects how reliable the sub-policies are.
SUBPOLICY_PRIORS = {"local": DEFAULT_PRIOR, "learned": "cpu_learned"}
#: LEAPS's N the commands use with each kind of sub-policy, tuned on the validation episodes beside ψ_obs
#: (docs/training.md, session 34; results/obs_noise_goal_mem60_v2.md): the paper's 30 for the local expert, 60 for
#: the map-goal network.
SUBPOLICY_REPLAN_EVERY = {"local": 30, "learned": 60}
#: Observation rules of :class:`LeapsAgent` (see :class:`leaps_mj.planning.semantic.SemanticModel`).
RULES = ("paper", "release")
#: Steps after which the local expert gives up on an exploration goal.
EXPLORE_PATIENCE = 40
#: How far inside a room (metres) the local expert walks before choosing its next room.
_ROOM_DEPTH = 0.6


@runtime_checkable
class SubPolicy(Protocol):
    """μ(target): a policy that walks to a room of a given type."""

    def reset(self, target: str) -> None:
        """Starts a new run towards a room of type ``target``."""

    def act(self, timestep) -> int:
        """The action for this time step."""


@runtime_checkable
class Agent(Protocol):
    """An agent solving RoomNav episodes."""

    name: str

    def reset(self, target: str) -> None:
        """Starts an episode whose target room type is ``target``."""

    def step(self, timestep) -> int:
        """The action for this time step."""

    def info(self) -> dict:
        """``{"subtarget": str | None, "plan": list[str], "belief": np.ndarray | None}``."""


def _check_target(target: str, allowed: tuple[str, ...] = rooms.ROOM_TYPES) -> str:
    """A target among ``allowed`` (default the room types :data:`rooms.ROOM_TYPES`), or ValueError.

    Agents that only run one sub-policy or the expert also take the untyped
    ``indoor`` node (``allowed=rooms.GRAPH_NODES``): the hop benchmark measures
    the hallway hops LEAPS plans through.
    """
    if target not in allowed:
        raise ValueError(f"unknown target {target!r}; expected one of {list(allowed)}")
    return target


class RandomAgent:
    """Uniformly random actions from a seeded generator.

    Args:
      seed: seed of the action draws.
    """

    name = "random"

    def __init__(self, seed: int = 0):
        self.rng = np.random.default_rng(seed)
        self.target: str | None = None

    def reset(self, target: str) -> None:
        self.target = _check_target(target, rooms.GRAPH_NODES)

    def step(self, timestep) -> int:
        del timestep
        return int(self.rng.integers(rooms.NUM_ACTIONS))

    def info(self) -> dict:
        return {"subtarget": None, "plan": [], "belief": None}


class PureAgent:
    """The "pure μ(θ)" baseline: runs the target's sub-policy for the whole episode.

    Args:
      subpolicy: any :class:`SubPolicy`.
    """

    name = "pure"

    def __init__(self, subpolicy: SubPolicy):
        self.subpolicy = subpolicy
        self.target: str | None = None

    def reset(self, target: str) -> None:
        self.target = _check_target(target, rooms.GRAPH_NODES)
        self.subpolicy.reset(target)

    def step(self, timestep) -> int:
        return int(self.subpolicy.act(timestep))

    def info(self) -> dict:
        return {"subtarget": self.target, "plan": [], "belief": None}


class OracleAgent:
    """The privileged geodesic expert (:class:`leaps_mj.environment.expert.GeodesicExpert`): an upper bound.

    Args:
      env: the environment it acts in (its state is read directly).
      seed: seed of the expert's unsticking moves.
    """

    name = "oracle"
    expert_class = expert.GeodesicExpert

    def __init__(self, env, seed: int = 0):
        self.expert = self.expert_class(env, seed=seed)
        self.target: str | None = None

    def reset(self, target: str) -> None:
        self.target = _check_target(target, rooms.GRAPH_NODES)
        self.expert.reset()

    def step(self, timestep) -> int:
        return self.expert.act(timestep)

    def info(self) -> dict:
        return {"subtarget": self.target, "plan": [], "belief": None}


class ScanningOracleAgent(OracleAgent):
    """The geodesic expert turning left whenever the way is out of view
    (:class:`leaps_mj.environment.expert.ScanningGeodesicExpert`): the ``geodesic-scan`` teacher, as an agent.
    """

    name = "oracle-scan"
    expert_class = expert.ScanningGeodesicExpert


class LookingOracleAgent(OracleAgent):
    """The geodesic expert looking around each room until the target is seen
    (:class:`leaps_mj.environment.looking_expert.LookingGeodesicExpert`): the ``geodesic-look`` teacher, as an agent.
    """

    name = "oracle-look"
    expert_class = looking_expert.LookingGeodesicExpert


class ObservableAgent(OracleAgent):
    """The observable expert (:class:`leaps_mj.environment.observable_expert.ObservableExpert`).

    It walks with the map but chooses where to go only from the rooms seen
    and the doors passed so far: the teacher a sub-policy can imitate, and
    what a learner of it could reach at best.
    """

    name = "observable"
    expert_class = observable_expert.ObservableExpert


class MapWalkAgent:
    """The map-goal sub-policy's walk with goals from elsewhere than its network (a teacher, a rule).

    A :class:`leaps_mj.environment.map_navigation.GoalDriver` builds the
    agent's own map from its frames (subsampled to ``width`` x ``height``, the
    shipped network's resolution) and walks to the goals :meth:`goal` gives,
    choosing a new one when the driver asks for it.

    Args:
      seed: seed of the planner's unsticking moves.
      width, height: resolution of the frames its map is built from.
    """

    #: Whether the walk's map marks the target's cues and every room type's see-objects (``GoalDriver``'s options).
    cues = False
    semantic = False

    def __init__(self, seed: int = 0, width: int = 40, height: int = 30):
        self.width, self.height = width, height
        self.seed = seed
        self.driver: map_navigation.GoalDriver | None = None
        self.target: str | None = None

    def reset(self, target: str) -> None:
        self.target = _check_target(target, rooms.GRAPH_NODES)
        self.driver = map_navigation.GoalDriver(self.target, self.width, self.height, cues=self.cues,
                                                semantic=self.semantic)
        self.driver.reset(self.seed)

    def step(self, timestep) -> int:
        self.driver.observe(timestep.observation)
        return self._act()

    def _act(self) -> int:
        """This step's action, the frame already on the map."""
        goal = self.goal()  # every step: a teacher's memory updates
        if self.driver.needs_goal():
            self.driver.set_goal(goal)
        return self.driver.act()

    def goal(self) -> int:
        """The goal at this step, a row-major index into the driver's egocentric window."""
        raise NotImplementedError

    def info(self) -> dict:
        return {"subtarget": self.target, "plan": [], "belief": None}


class MapOracleAgent(MapWalkAgent):
    """The map-goal sub-policy's walk with the teacher's goals instead of the network's: its ceiling.

    The goals are those of :class:`leaps_mj.environment.goal_teacher.TeacherGoals`,
    which read the house's map.

    Args:
      env: the environment it acts in (the teacher reads its state).
      seed: seed of the planner's unsticking moves.
      width, height: resolution of the frames its map is built from.
    """

    name = "oracle-map"
    teacher_class = goal_teacher.TeacherGoals

    def __init__(self, env, seed: int = 0, width: int = 40, height: int = 30):
        super().__init__(seed, width, height)
        self.teacher = self.teacher_class(env, seed)

    def goal(self) -> int:
        return self.teacher.cell(self.driver.mapper, self.driver.pose)


class ObservableMapOracleAgent(MapOracleAgent):
    """The map-goal walk with the observable teacher's goals
    (:class:`leaps_mj.environment.goal_teacher.ObservableTeacherGoals`): the ceiling of a network trained on them."""

    name = "oracle-map-observable"
    teacher_class = goal_teacher.ObservableTeacherGoals


class FurnitureMapOracleAgent(MapOracleAgent):
    """The map-goal walk with :class:`leaps_mj.environment.goal_teacher.FurnitureTeacherGoals`: the
    observable teacher with rooms revealed by their furniture only."""

    name = "oracle-map-furniture"
    teacher_class = goal_teacher.FurnitureTeacherGoals


class SensedMapOracleAgent(MapOracleAgent):
    """The map-goal walk with :class:`leaps_mj.environment.goal_teacher.SensedTeacherGoals`: the
    observable teacher with rooms revealed by their furniture and only the doors on the agent's map."""

    name = "oracle-map-sensed"
    teacher_class = goal_teacher.SensedTeacherGoals


class GatedMapOracleAgent(MapOracleAgent):
    """The map-goal walk with :class:`leaps_mj.environment.goal_teacher.GatedTeacherGoals`: the
    geodesic teacher's door, taken only once the agent has mapped it."""

    name = "oracle-map-gated"
    teacher_class = goal_teacher.GatedTeacherGoals


class PotentialMapOracleAgent(MapOracleAgent):
    """The map-goal walk with goals read off the teacher's potential
    (:func:`leaps_mj.environment.goal_teacher.potential_goal` on
    :meth:`leaps_mj.environment.goal_teacher.TeacherGoals.labels`): the ceiling of a network with a
    potential head, which picks its goals the same way from its prediction."""

    name = "oracle-map-potential"

    def goal(self) -> int:
        return goal_teacher.potential_goal(self.teacher.labels(self.driver.mapper, self.driver.pose, potential=True)[1])


#: Turns of :class:`FrontierAgent`'s first look around (30° each: a full circle).
SCAN_TURNS = 12


class FrontierAgent(MapWalkAgent):
    """The map-goal walk with frontier goals (:class:`leaps_mj.environment.frontier.FrontierGoals`):
    the same driver as the map-goal sub-policy, its goals chosen by rule from its own map, not learned.

    It first turns a full circle (:data:`SCAN_TURNS` turns, fewer once objects
    only the target's type has are mapped), so that the frontiers and targets
    it then chooses from include those behind it.

    Args:
      seed: seed of the planner's unsticking moves.
      width, height: resolution of the frames its map is built from.
    """

    name = "frontier"
    cues = True
    semantic = True

    def __init__(self, seed: int = 0, width: int = 40, height: int = 30):
        super().__init__(seed, width, height)
        self.goals = frontier.FrontierGoals()

    def reset(self, target: str) -> None:
        super().reset(target)
        self.goals.reset()
        self._turns = 0

    def _act(self) -> int:
        if self._turns < SCAN_TURNS and not self.goals.target_confirmed(self.driver.mapper):
            self._turns += 1
            return expert.LEFT
        self._turns = SCAN_TURNS
        return super()._act()

    def goal(self) -> int:
        return self.goals.cell(self.driver)


@dataclasses.dataclass(frozen=True)
class Replan:
    """One planning decision of :class:`LeapsAgent` (for case studies and tests).

    Attributes:
      step: agent step (0-based) at which it planned.
      reason: "start", "window" (N steps passed), "reached" (sub-target room
        entered) or "target" (target room entered before the sub-target).
      here: names of the nodes the agent was in.
      plan: node names of the chosen path, from a node in ``here`` to the target.
      subtarget: the sub-target it then ran the sub-policy for.
      belief: the posterior the plan was made on (9x9).
      n_pos, n_neg: the model's observation counts then (9x9), enough to
        rebuild the model as it was (e.g. for :func:`leaps_mj.planning.semantic.plot_belief`).
    """

    step: int
    reason: str
    here: tuple[str, ...]
    plan: tuple[str, ...]
    subtarget: str
    belief: np.ndarray
    n_pos: np.ndarray
    n_neg: np.ndarray


def subpolicy_defaults(subpolicy: str, prior: str | None = None, replan_every: int | None = None) -> tuple[str, int]:
    """LEAPS's prior and N for ``subpolicy`` ("local" or "learned"), each where not given (None)."""
    return (prior or SUBPOLICY_PRIORS[subpolicy],
            SUBPOLICY_REPLAN_EVERY[subpolicy] if replan_every is None else replan_every)


def current_nodes(bits) -> list[int]:
    """Graph nodes the agent is in, from one step's 8 room-type bits.

    All bits off means untyped indoor space, the ``indoor`` node.
    """
    on = np.flatnonzero(np.asarray(bits))
    return [int(i) for i in on] if on.size else [rooms.room_index(rooms.INDOOR)]


class LeapsAgent:
    """LEAPS: plan on the semantic model, act with sub-policies, update on experience.

    The agent decides at the first step, when it enters the sub-target's
    room ("reached"), when it enters a target room ("target"), and when a
    sub-policy run has gone on for ``replan_every`` steps since the last
    decision ("window"). A decision (1) updates the posterior, (2) plans the
    most probable path from the nodes the agent is in now to the target and
    (3) runs the sub-policy of the path's first hop (of the target itself once
    the agent is in a target room). The sub-policy is reset only when the
    sub-target changes; a replan that keeps the sub-target lets the same run
    continue (its recurrent state intact).

    Observation rules (``rule``):

    * ``"paper"``: at each "window" decision, B = OR of the semantic bits
      since the previous such observation
      (:func:`leaps_mj.planning.semantic.seen_vector`); pairs both in B are observed
      connected, pairs with exactly one in B not connected. Early decisions
      do not observe: a window cut short on entering the sub-target would
      count every edge of the room just entered as "not connected" after a
      few steps in it. Consecutive windows share their boundary step, so a
      room change at a boundary is still seen as a pair.
    * ``"release"`` (the original code): one observation of the edge from the
      run's start node to its sub-target, positive when the sub-target was
      reached, negative when ``replan_every`` steps passed without reaching it.

    Args:
      subpolicy: any :class:`SubPolicy`.
      model: the :class:`leaps_mj.planning.semantic.SemanticModel` (reset per episode).
      replan_every: N, steps per window (paper: 30).
      rule: "paper" or "release".

    Attributes:
      history: the :class:`Replan` decisions of the current episode.
    """

    name = "leaps"

    def __init__(self, subpolicy: SubPolicy, model: semantic.SemanticModel, replan_every: int = 30,
                 rule: str = "paper"):
        if isinstance(replan_every, bool) or not isinstance(replan_every, int) or replan_every < 1:
            raise ValueError(f"replan_every {replan_every!r}: expected a positive integer")
        if rule not in RULES:
            raise ValueError(f"rule {rule!r}: expected one of {list(RULES)}")
        self.subpolicy = subpolicy
        self.model = model
        self.replan_every = replan_every
        self.rule = rule
        self.target: str | None = None
        self._reset_state()

    def _reset_state(self) -> None:
        self.history: list[Replan] = []
        self._steps = 0
        self._run_steps = 0
        self._since_observed: list[np.ndarray] = []
        self._plan: list[int] = []
        self._subtarget: int | None = None
        self._belief: np.ndarray | None = None

    def reset(self, target: str) -> None:
        self.target = _check_target(target)
        self._target_node = rooms.room_index(target)
        self.model.reset()
        self._reset_state()

    def step(self, timestep) -> int:
        if self.target is None:
            raise ValueError("LeapsAgent.step called before reset(target)")
        obs = timestep.observation
        bits = np.asarray(obs["semantic"], dtype=bool)
        if bits.shape != (rooms.NUM_ROOM_TYPES,):
            raise ValueError(f"semantic bits of shape {bits.shape}; expected ({rooms.NUM_ROOM_TYPES},)")
        shown = np.flatnonzero(np.asarray(obs["target"]))
        if shown.tolist() != [self._target_node]:
            raise ValueError(f"observation target {np.asarray(obs['target']).tolist()} does not match the "
                             f"episode target {self.target!r} given to reset()")
        self._since_observed.append(bits)
        here = current_nodes(bits)
        reason = self._replan_reason(here)
        if reason is not None:
            self._observe(reason)
            self._replan(here, reason)
        self._steps += 1
        self._run_steps += 1
        return int(self.subpolicy.act(timestep))

    def _replan_reason(self, here: list[int]) -> str | None:
        """Why the agent must decide again at this step, or None to keep going."""
        if self._subtarget is None:
            return "start"
        if self._target_node in here and self._subtarget != self._target_node:
            return "target"
        if self._subtarget in here and self._subtarget != self._target_node:
            return "reached"
        if self._run_steps >= self.replan_every:
            return "window"
        return None

    def _observe(self, reason: str) -> None:
        """Updates the model at a decision (see the class docstring for what each rule observes)."""
        if self.rule == "paper":
            if reason == "window":
                self.model.observe_bits(semantic.seen_vector(np.stack(self._since_observed)))
                self._since_observed = self._since_observed[-1:]
        elif len(self._plan) > 1 and reason in ("reached", "window"):
            self.model.observe_subtarget_outcome(self._plan[0], self._subtarget, reason == "reached")

    def _replan(self, here: list[int], reason: str) -> None:
        """Plans from ``here`` and switches sub-policy if the sub-target changed."""
        self._run_steps = 0
        self._belief = self.model.posterior()
        plan = self.model.plan(here, self._target_node)
        subtarget = plan[1] if len(plan) > 1 else plan[0]
        if subtarget != self._subtarget:
            self.subpolicy.reset(rooms.GRAPH_NODES[subtarget])
        self._plan, self._subtarget = plan, subtarget
        self.history.append(Replan(
            step=self._steps, reason=reason, here=tuple(rooms.GRAPH_NODES[n] for n in here),
            plan=tuple(rooms.GRAPH_NODES[n] for n in plan), subtarget=rooms.GRAPH_NODES[subtarget],
            belief=self._belief, n_pos=self.model.n_pos.copy(), n_neg=self.model.n_neg.copy(),
        ))

    def info(self) -> dict:
        return {
            "subtarget": None if self._subtarget is None else rooms.GRAPH_NODES[self._subtarget],
            "plan": [rooms.GRAPH_NODES[n] for n in self._plan],
            "belief": self._belief,
        }


@dataclasses.dataclass(frozen=True)
class _Rooms:
    """Walking goal: well inside any of these rooms (ids)."""

    ids: tuple[int, ...]


@dataclasses.dataclass(frozen=True)
class _Cell:
    """Walking goal: one cell of the wide-clearance navigation grid."""

    ij: tuple[int, int]


class _Walker(expert.GeodesicExpert):
    """The geodesic expert, also able to walk into given rooms or to a given cell.

    ``step_towards(goal, False, pose)`` with a :class:`_Rooms` goal follows
    the distance field to the part of those rooms at least
    :data:`_ROOM_DEPTH` metres from their edges, so a walk ends inside a room,
    where its semantic bit is on, not on the threshold of a doorway; with a
    :class:`_Cell` goal, to that cell. It returns None at the goal. A
    room-type name works as in the parent class. Room fields are cached per
    house; only the latest cell field is kept.
    """

    _cell_field: tuple = (None, None)

    def field(self, target, view):
        if isinstance(target, str):
            return super().field(target, view)
        hm = self.env.task.house_model
        key = (hm.house.id, target)
        if key in self._fields:
            return self._fields[key]
        if self._cell_field[0] == key:
            return self._cell_field[1]
        grid = hm.grid
        if isinstance(target, _Cell):
            zone = np.zeros(grid.shape, dtype=bool)
            zone[target.ij] = True
        else:
            room = np.isin(grid.room_id, target.ids)
            deep = room & grid.free & (scipy.ndimage.distance_transform_edt(room) * grid.cell >= _ROOM_DEPTH)
            zone = deep if deep.any() else room & grid.free
        value = (*self.zone_field(zone), np.zeros((0, 2)))
        if isinstance(target, _Cell):
            self._cell_field = (key, value)
        else:
            self._fields[key] = value
        return value


class LocalExpertPolicy:
    """A privileged sub-policy that is good near its target and poor far from it.

    Stands in for a learned sub-policy: when the agent's current room is of
    the requested type or one door away from one
    (:meth:`leaps_mj.environment.roomnav.HouseModel.plan_length` <= 1), it walks the
    geodesic path like :class:`leaps_mj.environment.expert.GeodesicExpert` (for the
    episode's own target including the "see" behaviour: face the target's
    objects and stay; for another room type, into the room until its
    semantic bit is surely on, then stay). Farther away it wanders, a
    persistent random walk: it walks to a uniformly drawn free point between
    1 m and ``explore_radius`` metres (straight-line) from where it stands,
    then draws the next (also after :data:`EXPLORE_PATIENCE` steps without
    arriving). It passes doors only when a drawn point lies beyond one, so,
    like a learned policy far from its target, it finds distant rooms slowly.
    (A walk from room to neighbouring room through doors would be a far
    better explorer than any learned policy: with it, this "pure" baseline
    solved 91% of 80 test episodes of an earlier roomnav-v1 within 300
    steps, leaving planning nothing to add.)

    Args:
      env: the :class:`leaps_mj.environment.roomnav.RoomNavEnvironment` it acts in.
      seed: seed of the exploration draws and unsticking moves.
      explore_radius: farthest exploration goal, metres.

    Attributes:
      mode: "expert" or "explore" at the last action (None before).
      goal: world (x, y) of the current exploration goal (None in expert mode).
    """

    def __init__(self, env, seed: int = 0, explore_radius: float = 3.0):
        if not explore_radius > 1.0:
            raise ValueError(f"explore_radius {explore_radius!r}: expected more than 1 metre")
        self.env = env
        self.explore_radius = explore_radius
        self.rng = np.random.default_rng(seed)
        self.walker = _Walker(env, seed=int(self.rng.integers(2**31)))
        self.target: str | None = None
        self.mode: str | None = None
        self.goal: np.ndarray | None = None
        self._goal: _Cell | None = None
        self._goal_steps = 0

    def reset(self, target: str) -> None:
        rooms.room_index(target)
        self.target = target
        self.mode = None
        self.goal = self._goal = None
        self._goal_steps = 0

    def act(self, timestep) -> int:
        del timestep
        if self.target is None:
            raise ValueError("LocalExpertPolicy.act called before reset(target)")
        task = self.env.task
        hm = task.house_model
        pose = self.env.physics.agent_pose()
        room = hm.room_at(pose[:2])
        hops = hm.plan_length(room, self.target) if room >= 0 else None
        if hops is not None and hops <= 1:
            self.mode, self.goal, self._goal = "expert", None, None
            if self.target == task.episode.target:
                return self.walker.act()
            goal = _Rooms(tuple(r.id for r in hm.house.rooms if r.type == self.target))
            action = self.walker.step_towards(goal, False, pose)
            return expert.STAY if action is None else int(action)
        self.mode = "explore"
        action = None
        if self._goal is not None and self._goal_steps < EXPLORE_PATIENCE:
            action = self.walker.step_towards(self._goal, False, pose)
        if action is None:  # no goal yet, arrived, or gave up: draw the next one
            self._draw_goal(hm, pose)
            self._goal_steps = 0
            action = self.walker.step_towards(self._goal, False, pose)
            if action is None:
                action = expert.FORWARD
        self._goal_steps += 1
        return int(action)

    def _draw_goal(self, hm, pose) -> None:
        """A uniformly drawn free cell 1 m to ``explore_radius`` from the agent."""
        safe = self.walker._safe_grid(hm)
        xs, ys = safe.cell_centers()
        d = np.hypot(xs - pose[0], ys - pose[1])
        cells = np.flatnonzero((safe.free & (d >= 1.0) & (d <= self.explore_radius)).ravel())
        if cells.size == 0:  # a cramped corner: any free cell of the house
            cells = np.flatnonzero(safe.free.ravel())
        ij = np.unravel_index(self.rng.choice(cells), safe.shape)
        self._goal = _Cell((int(ij[0]), int(ij[1])))
        self.goal = safe.to_world(ij)


def prior_path(prior: str) -> pathlib.Path:
    """The file of a shipped prior (``"cpu"`` -> ``leaps_mj/data/prior_cpu.json``) or a given path."""
    if os.sep in prior or prior.endswith(".json"):
        return pathlib.Path(prior)
    return rooms.DATA_DIR / f"prior_{prior}.json"


def load_model(prior: str = DEFAULT_PRIOR) -> semantic.SemanticModel:
    """The semantic model for the LEAPS agent.

    Args:
      prior: name of a shipped prior (default ``"cpu"``: learned by
        ``python -m leaps_mj.train prior --preset cpu`` on the training
        houses), ``"reference"`` for the original release's SUNCG prior with
        the paper's noise, or a path to a :meth:`SemanticModel.to_json` file.

    Raises:
      ValueError: if the prior file is missing or invalid.
    """
    if prior == "reference":
        return semantic.SemanticModel.from_reference()
    path = prior_path(prior)
    if not path.is_file():
        raise ValueError(f"no prior file {str(path)!r} (prior {prior!r}); expected a shipped prior name "
                         "(learn one with `python -m leaps_mj.train prior`), 'reference', or a JSON path")
    return semantic.SemanticModel.from_json(path)
