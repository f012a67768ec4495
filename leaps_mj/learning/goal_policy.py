"""The map-goal sub-policy: a learned network picks where to walk on the agent's own map, a planner walks there.

Sessions 4–7 (docs/training.md) found the end-to-end CNN+LSTM sub-policies
stuck near 50 % one-door hop success: they dither between turns and guess
doors, and imitation of the teachers at 0.2–0.3 M samples a target did not
teach them to keep memory or to commit. This sub-policy splits the skill the
way modular navigation agents do:

* :class:`leaps_mj.environment.mapping.EgoMapper` keeps the memory — a
  top-down map of what the frames showed, around the agent;
* :class:`leaps_mj.nets.GoalNet <leaps_mj.learning.nets.GoalNet>`, the learned part, scores
  every cell of that map as the place to head for next (the target's
  objects once seen; otherwise the door the geodesic teacher would take, as
  well as the map lets it guess), every
  :data:`leaps_mj.environment.map_navigation.REPLAN` steps, never mid-turn;
* :class:`leaps_mj.environment.map_navigation.MapNavigator` walks there over
  the cells not seen blocked; at the goal the sub-policy faces the nearest
  mapped object of the target and stops where it fills the frame.

It reads the observation only (segmentation, depth, ``pose``, ``collision``;
a network trained with ``room_bits``, the semantic-augmented μ_s, also the
``semantic`` bits) and has the sub-policy interface (``reset(target)``, ``act(timestep)``,
``seed``), so LEAPS, the baselines and the hop benchmark drive it as they
drive :class:`leaps_mj.learning.policies.LearnedSubPolicy`. The checkpoint is
one ``goal.pt`` serving every graph node, trained by
:mod:`leaps_mj.learning.train_goal`.
"""

from __future__ import annotations

import os
import pathlib

import torch

from leaps_mj.environment import goal_teacher, map_navigation, mapping
from leaps_mj.learning import checkpoints, nets
from leaps_mj.world import rooms

#: File name of the map-goal network in a policy folder.
GOAL = "goal.pt"
#: Folder of the shipped map-goal network (cpu preset, 40x30 maps).
DEFAULT_DIR = rooms.DATA_DIR / "policies" / "goal_cpu"
#: Steps of a run after which the map is built afresh, for a network whose metadata does not name the
#: horizon of its training runs (:class:`GoalSubPolicy`'s ``memory``).
MEMORY = 60
#: The command that trains it (session 19's recipe, 2.2 h on 2 cores; docs/training.md).
TRAIN_COMMAND = (f"python -m leaps_mj.train goal --preset cpu --threads 2 && cp runs/goal/{GOAL} {DEFAULT_DIR}/")


@torch.no_grad()
def choose_goal(net: nets.GoalNet, driver: map_navigation.GoalDriver, window, bits=None) -> int:
    """The network's goal for the driver's current map, as a row-major window cell.

    With ``goals`` ``logits`` (``nets.GoalNetConfig``), the cell of the highest goal logit; with
    ``potential``, the end of the walk down its predicted potential
    (:func:`leaps_mj.environment.goal_teacher.potential_goal`): the way towards where the target most
    likely lies, as the teacher's goal is the way down the true one.

    Args:
      net: The map-goal network.
      driver: The run's driver, after :meth:`~leaps_mj.environment.map_navigation.GoalDriver.observe`.
      window: The map ``observe`` returned.
      bits: The observation's room-type bits, for a network that reads them (None otherwise).
    """
    bits = torch.as_tensor(bits[None]) if bits is not None else None
    logits, potential = net.heads(torch.as_tensor(window[None]), torch.tensor([driver.node]), bits)
    if net.config.goals == "logits":
        return int(logits.argmax())
    return goal_teacher.potential_goal(potential[0].numpy())


def load_goal_net(path: str | os.PathLike, width: int | None = None,
                  height: int | None = None) -> tuple[nets.GoalNet, dict]:
    """A map-goal network and its training metadata.

    Raises:
      ValueError: if the file is missing, not a map-goal network, or of another resolution than asked.
    """
    path = pathlib.Path(path)
    if not path.is_file():
        raise ValueError(f"no map-goal network at {path}; train one with `python -m leaps_mj.train goal`")
    model, _, extra = checkpoints.load_policy(path, width, height)
    if not isinstance(model, nets.GoalNet):
        raise ValueError(f"{path} holds a {type(model).__name__}, not a map-goal network (GoalNet)")
    if model.config.map_channels != len(mapping.CHANNELS) or model.config.window != mapping.WINDOW:
        raise ValueError(f"{path} reads {model.config.map_channels}-channel {model.config.window}-cell maps; this "
                         f"code builds {len(mapping.CHANNELS)}-channel {mapping.WINDOW}-cell maps")
    return model, extra


class GoalSubPolicy:
    """The map-goal sub-policy behind the sub-policy interface, for every graph node.

    The network was trained on runs of at most ``horizon`` steps from an empty map. Over longer runs the map
    fills with what it never saw in training (long trails of visited cells, rooms mapped hundreds of steps
    before), and it loops within a few metres: on the 1,000 test episodes, run alone, it reached 51 % at
    H = 1000 and 49 % at H = 300 (session 33, docs/training.md). So every ``memory`` steps of a run the map is
    forgotten and built afresh from the next frame, as at the start of a run: 77 % at H = 1000. Runs no longer
    than that (the hop benchmark's 60 steps) are unchanged; LEAPS, whose runs end at each sub-target switch,
    gains less.

    Args:
      path: A ``goal.pt`` written by ``python -m leaps_mj.train goal`` (or a folder holding one).
      seed: Seed of the planner's unsticking moves.
      memory: Steps of a run after which its map is built afresh. None: the horizon of the network's
        training runs (its metadata's ``train_config``, else :data:`MEMORY`). 0: never.

    Attributes:
      width, height: Frame resolution the network's maps are built from;
        frames of an integer multiple of it are subsampled.
      targets: The graph nodes it serves (all of them).
      memory: As the argument, resolved.

    Raises:
      ValueError: for a negative ``memory``, or as :func:`load_goal_net`.
    """

    def __init__(self, path: str | os.PathLike, seed: int = 0, memory: int | None = None):
        path = pathlib.Path(path)
        self.net, self.metadata = load_goal_net(path / GOAL if path.is_dir() else path)
        if memory is None:
            memory = int(self.metadata.get("train_config", {}).get("horizon", MEMORY))
        if isinstance(memory, bool) or not isinstance(memory, int) or memory < 0:
            raise ValueError(f"memory {memory!r}: expected a non-negative number of steps (0: never forget)")
        self.memory = memory
        self.width, self.height = self.net.config.width, self.net.config.height
        self.targets = rooms.GRAPH_NODES
        self._seed = seed
        self._drivers: dict[str, map_navigation.GoalDriver] = {}
        self._driver: map_navigation.GoalDriver | None = None

    @property
    def goal(self):
        """World (x, y) of the goal the current run heads for, a copy (None before its first choice)."""
        if self._driver is None or self._driver.goal is None:
            return None
        return self._driver.goal.copy()

    def seed(self, seed: int) -> None:
        """Restarts the planner's unsticking moves from ``seed`` at the next :meth:`reset`."""
        self._seed = seed

    def reset(self, target: str) -> None:
        """Starts a run towards ``target`` with an empty map.

        Raises:
          ValueError: for an unknown graph node.
        """
        if target not in rooms.GRAPH_NODES:
            raise ValueError(f"no sub-policy for target {target!r}; expected one of {list(rooms.GRAPH_NODES)}")
        if target not in self._drivers:
            config = self.net.config
            self._drivers[target] = map_navigation.GoalDriver(target, self.width, self.height,
                                                              context=config.context, cues=config.cues,
                                                              semantic=config.semantic)
        self._driver = self._drivers[target]
        self._driver.reset(self._seed)

    @torch.no_grad()
    def act(self, timestep) -> int:
        """The action for a time step's observation.

        Raises:
          ValueError: before :meth:`reset`, or for frames of another resolution.
        """
        if self._driver is None:
            raise ValueError("call reset(target) before act()")
        if self.memory and self._driver.steps >= self.memory:
            self._driver.reset()  # a fresh map; the unsticking moves' random stream goes on
        window = self._driver.observe(timestep.observation)
        if self._driver.needs_goal():
            bits = timestep.observation["semantic"] if self.net.config.room_bits else None
            self._driver.set_goal(choose_goal(self.net, self._driver, window, bits))
        return self._driver.act()


def load_default(seed: int = 0) -> GoalSubPolicy:
    """The shipped map-goal sub-policy (``leaps_mj/data/policies/goal_cpu/goal.pt``).

    Raises:
      ValueError: if the shipped network is missing, naming the command that trains it.
    """
    if not (DEFAULT_DIR / GOAL).is_file():
        raise ValueError(f"no shipped map-goal network in {DEFAULT_DIR}; train it with `{TRAIN_COMMAND}`")
    return GoalSubPolicy(DEFAULT_DIR, seed=seed)
