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
  well as the map lets it guess), every :data:`REPLAN` steps;
* :class:`leaps_mj.environment.map_navigation.MapNavigator` walks there over
  the cells not seen blocked; at the goal the sub-policy faces the nearest
  mapped object of the target and stops where it fills the frame.

It reads the observation only (segmentation, depth, ``pose``, ``collision``)
and has the sub-policy interface (``reset(target)``, ``act(timestep)``,
``seed``), so LEAPS, the baselines and the hop benchmark drive it as they
drive :class:`leaps_mj.learning.policies.LearnedSubPolicy`. The checkpoint is
one ``goal.pt`` serving every graph node, trained by
:mod:`leaps_mj.learning.train_goal`.
"""

from __future__ import annotations

import math
import os
import pathlib

import numpy as np
import torch

from leaps_mj.environment import expert, map_navigation, mapping, roomnav
from leaps_mj.learning import nets
from leaps_mj.world import rooms

#: File name of the map-goal network in a policy folder.
GOAL = "goal.pt"
#: Steps between two goal choices (the planner walks to the last goal in between).
REPLAN = 4
#: Share of the frame the target's objects must fill for the sub-policy to stop and look (the see test's).
SEE_FRACTION = roomnav.EnvConfig.success_fraction


class GoalDriver:
    """One run's map, planner and goal: turns observations and chosen goals into actions.

    The sub-policy gives it goals from the network; the trainer from the
    network or from the teacher. Call :meth:`observe` with each step's
    observation, then :meth:`set_goal` when :meth:`needs_goal`, then :meth:`act`.

    Args:
      target: The graph node of the run.
      width, height: Resolution of the frames it is given.
      seed: Seed of the planner's unsticking moves.
    """

    def __init__(self, target: str, width: int, height: int, seed: int = 0):
        self.target = target
        self.node = rooms.GRAPH_NODES.index(target)
        self.mapper = mapping.EgoMapper(target, width, height)
        self.navigator = map_navigation.MapNavigator(self.mapper, seed)
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
        self.pose = np.zeros(3)
        self._collided = False
        self._fraction = 0.0

    def observe(self, observation) -> np.ndarray:
        """Adds the step's frame to the map; returns the egocentric map (C, WINDOW, WINDOW)."""
        seg = np.asarray(observation["segmentation"])
        self.pose = np.asarray(observation["pose"], np.float64)
        self._collided = bool(observation["collision"]) and self.steps > 0
        self._fraction = float(self._see[seg].mean())
        return self.mapper.update(seg, observation["depth"], self.pose)

    def needs_goal(self) -> bool:
        """Whether this step chooses a new goal (the first step, then every :data:`REPLAN`)."""
        return self.goal is None or self.steps % REPLAN == 0

    def set_goal(self, cell: int) -> None:
        """Heads for a cell of the egocentric map (row-major index into the window) around the current pose."""
        row, col = divmod(int(cell), mapping.WINDOW)
        x, y = self.mapper.window_world(self.pose)
        self.goal = np.array([x[row, col], y[row, col]])

    def act(self) -> int:
        """The action of this step: walk to the goal; there, face the target's nearest mapped object."""
        self.steps += 1
        action = self.navigator.act(self.pose, self.goal, self._collided) if self.goal is not None else None
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
            return expert._turn(err)
        if self._fraction >= SEE_FRACTION:
            return expert.STAY
        return expert.SMALL_FORWARD if distance[k] > 1.0 else expert.STAY


def load_goal_net(path: str | os.PathLike, width: int | None = None,
                  height: int | None = None) -> tuple[nets.GoalNet, dict]:
    """A map-goal network and its training metadata.

    Raises:
      ValueError: if the file is missing, not a map-goal network, or of another resolution than asked.
    """
    path = pathlib.Path(path)
    if not path.is_file():
        raise ValueError(f"no map-goal network at {path}; train one with `python -m leaps_mj.train goal`")
    model, _, extra = nets.load_policy(path, width, height)
    if not isinstance(model, nets.GoalNet):
        raise ValueError(f"{path} holds a {type(model).__name__}, not a map-goal network (GoalNet)")
    if model.config.map_channels != len(mapping.CHANNELS) or model.config.window != mapping.WINDOW:
        raise ValueError(f"{path} reads {model.config.map_channels}-channel {model.config.window}-cell maps; this "
                         f"code builds {len(mapping.CHANNELS)}-channel {mapping.WINDOW}-cell maps")
    return model, extra


class GoalSubPolicy:
    """The map-goal sub-policy behind the sub-policy interface, for every graph node.

    Args:
      path: A ``goal.pt`` written by ``python -m leaps_mj.train goal`` (or a folder holding one).
      seed: Seed of the planner's unsticking moves.

    Attributes:
      width, height: Frame resolution the network's maps are built from;
        frames of an integer multiple of it are subsampled.
      targets: The graph nodes it serves (all of them).
    """

    def __init__(self, path: str | os.PathLike, seed: int = 0):
        path = pathlib.Path(path)
        self.net, self.metadata = load_goal_net(path / GOAL if path.is_dir() else path)
        self.width, self.height = self.net.config.width, self.net.config.height
        self.targets = rooms.GRAPH_NODES
        self._seed = seed
        self._drivers: dict[str, GoalDriver] = {}
        self._driver: GoalDriver | None = None

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
            self._drivers[target] = GoalDriver(target, self.width, self.height)
        self._driver = self._drivers[target]
        self._driver.reset(self._seed)

    def _frame(self, frame) -> np.ndarray:
        frame = np.asarray(frame)
        h, w = frame.shape[-2:]
        k = h // self.height
        if frame.ndim == 2 and k >= 1 and (h, w) == (k * self.height, k * self.width):
            return frame[k // 2::k, k // 2::k]
        raise ValueError(f"frame of shape {frame.shape}; this policy takes {self.width}x{self.height} frames "
                         f"(width x height) or an integer multiple of that size")

    @torch.no_grad()
    def act(self, timestep) -> int:
        """The action for a time step's observation.

        Raises:
          ValueError: before :meth:`reset`, or for frames of another resolution.
        """
        if self._driver is None:
            raise ValueError("call reset(target) before act()")
        obs = timestep.observation
        frames = {k: self._frame(obs[k]) for k in ("segmentation", "depth")}
        window = self._driver.observe({**frames, "pose": obs["pose"], "collision": obs["collision"]})
        if self._driver.needs_goal():
            logits = self.net(torch.as_tensor(window[None]), torch.tensor([self._driver.node]))
            self._driver.set_goal(int(logits.argmax()))
        return self._driver.act()
