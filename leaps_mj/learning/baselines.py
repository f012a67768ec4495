"""The paper's learned baselines: the semantic-augmented policy and the HRL agent with an LSTM controller.

Both follow the agent interface of :mod:`leaps_mj.planning.agents` (``name``,
``reset(target)``, ``step(timestep)``, ``info()``).

* :class:`AugmentedPolicyAgent` ("aug. μ_s"): runs one sub-policy towards the
  target for the whole episode, like the pure baseline, but that policy is
  μ_s, whose network also reads the semantic bits and the target
  (``nets.PolicyConfig(use_semantic=True)``): the semantic signal as a plain
  input instead of a model to plan on.
* :class:`ControllerAgent` ("RNN controller"): the same sub-policies as LEAPS,
  driven by a :class:`leaps_mj.learning.nets.ControllerNet` (LSTM, 50 units) instead of
  the semantic model. At the first step, every ``option_steps`` steps, and
  when it enters the room of its sub-target, the controller reads the current
  bits, the bits OR-accumulated since the episode began, the target one-hot
  and the last sub-target one-hot, and picks the next sub-target (one of the
  8 room types). Trained with A2C by ``python -m leaps_mj.train controller``.
"""

from __future__ import annotations

import dataclasses
import os
import pathlib

import numpy as np
import torch

from leaps_mj.learning import checkpoints, nets
from leaps_mj.planning import agents
from leaps_mj.world import rooms

K = rooms.NUM_ROOM_TYPES
#: The shipped controller (cpu preset).
DEFAULT_CONTROLLER = rooms.DATA_DIR / "controller" / "cpu.pt"
#: The command that trains it.
TRAIN_COMMAND = (f"python -m leaps_mj.train controller --preset cpu --out runs/controller_cpu && "
                 f"cp runs/controller_cpu/controller.pt {DEFAULT_CONTROLLER}")
#: Why a controller decision was taken.
REASONS = ("start", "option", "reached")


class AugmentedPolicyAgent(agents.PureAgent):
    """The "aug. μ_s" baseline: the semantic-augmented policy μ_s towards the target, throughout.

    Args:
      subpolicy: μ_s, a :class:`leaps_mj.planning.agents.SubPolicy` whose network reads
        ``observation["semantic"]`` and ``["target"]`` besides the pixels.
    """

    name = "aug"


def controller_inputs(bits, accumulated, target: int, last_subtarget: int | None) -> np.ndarray:
    """The controller's 4K input: current bits, OR-accumulated bits, target one-hot, last sub-target one-hot.

    ``last_subtarget`` None (no sub-target yet) gives a zero block.
    """
    x = np.zeros(4 * K, dtype=np.float32)
    x[:K] = np.asarray(bits, dtype=bool)
    x[K:2 * K] = np.asarray(accumulated, dtype=bool)
    x[2 * K + target] = 1.0
    if last_subtarget is not None:
        x[3 * K + last_subtarget] = 1.0
    return x


@dataclasses.dataclass(frozen=True)
class Decision:
    """One choice of the controller (what A2C trains on).

    Attributes:
      step: agent step (0-based) at which it chose.
      reason: "start", "option" (``option_steps`` passed) or "reached" (the
        sub-target's bit turned on).
      inputs: the (4K,) input it read.
      subtarget: index of the room type it chose.
    """

    step: int
    reason: str
    inputs: np.ndarray
    subtarget: int


class ControllerAgent:
    """HRL baseline: an LSTM controller choosing sub-targets for the sub-policies.

    An option (one sub-policy run) ends after ``option_steps`` steps, or
    earlier when the sub-target's bit turns on (it was off when the option
    began); the controller then chooses again, its LSTM state carried through
    the episode. The sub-policy is reset only when the sub-target changes.

    Args:
      subpolicy: any :class:`leaps_mj.planning.agents.SubPolicy`.
      net: the :class:`leaps_mj.learning.nets.ControllerNet`.
      option_steps: N, the longest option (steps).
      greedy: choose the most likely sub-target instead of sampling one.
      seed: seed of the sampling.

    Attributes:
      decisions: the :class:`Decision` s of the current episode.
    """

    name = "controller"

    def __init__(self, subpolicy: agents.SubPolicy, net: nets.ControllerNet, option_steps: int = 30,
                 greedy: bool = False, seed: int = 0):
        if isinstance(option_steps, bool) or not isinstance(option_steps, int) or option_steps < 1:
            raise ValueError(f"option_steps {option_steps!r}: expected a positive integer")
        if not isinstance(net, nets.ControllerNet) or net.config.num_room_types != K:
            raise ValueError(f"net {type(net).__name__}: expected a nets.ControllerNet over {K} room types")
        self.subpolicy = subpolicy
        self.net = net.eval()
        self.option_steps = option_steps
        self.greedy = greedy
        self._generator = torch.Generator().manual_seed(seed)
        self.target: str | None = None
        self.decisions: list[Decision] = []

    @classmethod
    def from_checkpoint(cls, subpolicy: agents.SubPolicy, path: str | os.PathLike = DEFAULT_CONTROLLER,
                        greedy: bool = False, seed: int = 0) -> "ControllerAgent":
        """The agent with a controller trained by ``python -m leaps_mj.train controller`` (its N included)."""
        net, extra = load_controller(path)
        return cls(subpolicy, net, option_steps=int(extra["option_steps"]), greedy=greedy, seed=seed)

    def reset(self, target: str) -> None:
        self.target = agents._check_target(target)
        self._target = rooms.room_index(target)
        self._state = self.net.initial_state(1)
        self._accumulated = np.zeros(K, dtype=bool)
        self._subtarget: int | None = None
        self._option_start = np.zeros(K, dtype=bool)
        self._option_length = 0
        self._steps = 0
        self.decisions = []

    def step(self, timestep) -> int:
        if self.target is None:
            raise ValueError("ControllerAgent.step called before reset(target)")
        bits = np.asarray(timestep.observation["semantic"], dtype=bool)
        if bits.shape != (K,):
            raise ValueError(f"semantic bits of shape {bits.shape}; expected ({K},)")
        self._accumulated |= bits
        if self._subtarget is None:
            self._decide(bits, "start")
        elif bits[self._subtarget] and not self._option_start[self._subtarget]:
            self._decide(bits, "reached")
        elif self._option_length >= self.option_steps:
            self._decide(bits, "option")
        self._option_length += 1
        self._steps += 1
        return int(self.subpolicy.act(timestep))

    @torch.no_grad()
    def _decide(self, bits: np.ndarray, reason: str) -> None:
        x = controller_inputs(bits, self._accumulated, self._target, self._subtarget)
        logits, _, self._state = self.net(torch.as_tensor(x)[None], self._state)
        if self.greedy:
            choice = int(logits[0].argmax())
        else:
            choice = int(torch.multinomial(torch.softmax(logits[0], -1), 1, generator=self._generator))
        if choice != self._subtarget:
            self.subpolicy.reset(rooms.ROOM_TYPES[choice])
        self._subtarget = choice
        self._option_start = bits.copy()
        self._option_length = 0
        self.decisions.append(Decision(self._steps, reason, x, choice))

    def info(self) -> dict:
        return {"subtarget": None if self._subtarget is None else rooms.ROOM_TYPES[self._subtarget],
                "plan": [], "belief": None}


def load_controller(path: str | os.PathLike = DEFAULT_CONTROLLER) -> tuple[nets.ControllerNet, dict]:
    """A trained controller and its checkpoint metadata (``option_steps``, ``subpolicy``, training config).

    Raises:
      ValueError: if the file is missing (naming the command that trains the
        shipped one) or holds another network.
    """
    path = pathlib.Path(path)
    if not path.is_file():
        hint = f"; train it with `{TRAIN_COMMAND}`" if path == DEFAULT_CONTROLLER else ""
        raise ValueError(f"no controller checkpoint {str(path)!r}{hint}")
    net, _, extra = checkpoints.load_policy(path)
    if not isinstance(net, nets.ControllerNet) or "option_steps" not in extra:
        raise ValueError(f"{path} is not a controller checkpoint of `python -m leaps_mj.train controller`")
    return net, extra
