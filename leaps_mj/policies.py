"""Learned sub-policies μ(θ): per-target actor-critics behind the SubPolicy interface.

A sub-policy has ``reset(target)`` (a new run towards a room type, or the
untyped ``indoor`` node; resets the LSTM state) and ``act(timestep) -> int``.
:class:`LearnedSubPolicy` holds one network per target, loaded from
``<folder>/<target>.pt`` as written by ``python -m leaps_mj.train policy``.
:func:`load_default` loads the
checkpoints shipped with the package (the ``cpu`` preset, 40x30 frames); they
act on 40x30 environments or on frames of an integer multiple of that size
(120x90), which they subsample.
"""

from __future__ import annotations

import os
import pathlib
from typing import Sequence

import numpy as np
import torch

from leaps_mj import nets, rooms

#: Folder of the shipped checkpoints (cpu preset).
DEFAULT_DIR = pathlib.Path(__file__).resolve().parent / "data" / "policies" / "cpu"
#: The command that trains them.
TRAIN_COMMAND = ("python -m leaps_mj.train policy --preset cpu --target all --out runs/policy_cpu && "
                 f"cp runs/policy_cpu/*.pt {DEFAULT_DIR}/")


class LearnedSubPolicy:
    """Per-target CNN+LSTM policies acting on segmentation + depth.

    Args:
      folder: Folder with one ``<target>.pt`` checkpoint per target.
      targets: Targets to load (default: the 8 room types and ``indoor``).
      greedy: Take the most likely action instead of sampling one.
      seed: Seed of the action sampling.
      width, height: If given, the resolution the checkpoints must have.

    Attributes:
      width, height: Frame resolution the networks take (make the
        environment with these).
      targets: The loaded room types.

    Raises:
      ValueError: if a checkpoint is missing, unreadable, of another
        resolution than asked, or the checkpoints disagree on resolution.
    """

    def __init__(self, folder: str | os.PathLike, targets: Sequence[str] = rooms.GRAPH_NODES,
                 greedy: bool = False, seed: int = 0, width: int | None = None, height: int | None = None):
        folder = pathlib.Path(folder)
        if not targets:
            raise ValueError("targets is empty: expected at least one room type")
        self.nets: dict[str, nets.ActorCritic] = {}
        self.metadata: dict[str, dict] = {}
        for target in targets:
            rooms.room_index(target)
            model, config, extra = nets.load_policy(folder / f"{target}.pt", width, height)
            if not isinstance(model, nets.ActorCritic) or config.use_semantic:
                raise ValueError(f"{folder / f'{target}.pt'} is not a pixel-only sub-policy ({type(model).__name__})")
            width, height = config.width, config.height
            self.nets[target] = model
            self.metadata[target] = extra
        self.width, self.height = width, height
        self.targets = tuple(targets)
        self.greedy = greedy
        self._generator = torch.Generator().manual_seed(seed)
        self._net: nets.ActorCritic | None = None
        self._state = None

    def seed(self, seed: int) -> None:
        """Restarts the action sampler from ``seed`` (e.g. per evaluated episode, so
        results do not depend on which episodes a process ran before)."""
        self._generator.manual_seed(seed)

    def reset(self, target: str) -> None:
        """Starts a run towards ``target``: switches network, zeroes the LSTM state.

        Raises:
          ValueError: for a room type without a loaded network.
        """
        if target not in self.nets:
            raise ValueError(f"no sub-policy for target {target!r}; loaded: {list(self.targets)}")
        self._net = self.nets[target]
        self._state = self._net.initial_state(1)

    def _frame(self, frame) -> np.ndarray:
        """The frame at the policy's resolution (subsampled from an integer multiple)."""
        frame = np.asarray(frame)
        h, w = frame.shape[-2:]
        k = h // self.height
        if frame.ndim == 2 and k >= 1 and (h, w) == (k * self.height, k * self.width):
            return frame[k // 2::k, k // 2::k]
        raise ValueError(f"frame of shape {frame.shape}; this policy takes {self.width}x{self.height} frames "
                         f"(width x height) or an integer multiple of that size")

    @torch.no_grad()
    def act(self, timestep) -> int:
        """The action for a time step's observation (segmentation + depth).

        Frames rendered at an integer multiple ``k`` of the policy's resolution
        (120x90 for the 40x30 shipped policies) are subsampled at the centre
        pixel of every k x k block: the same rays as rendering at the policy's
        resolution, so the same frame.

        Raises:
          ValueError: before :meth:`reset`, or for frames of another resolution.
        """
        if self._net is None:
            raise ValueError("call reset(target) before act()")
        obs = timestep.observation
        x = nets.ActorCritic.preprocess({k: self._frame(obs[k])[None] for k in ("segmentation", "depth")})
        logits, _, self._state = self._net(x, self._state)
        if self.greedy:
            return int(logits.argmax(-1))
        return int(torch.multinomial(torch.softmax(logits[0], -1), 1, generator=self._generator))


def load_default(greedy: bool = False, seed: int = 0) -> LearnedSubPolicy:
    """The shipped sub-policies (cpu preset, 40x30) for the 8 room types and ``indoor``.

    Raises:
      ValueError: if a shipped checkpoint is missing, naming the command that trains them.
    """
    missing = [t for t in rooms.GRAPH_NODES if not (DEFAULT_DIR / f"{t}.pt").is_file()]
    if missing:
        raise ValueError(f"no shipped sub-policy checkpoints for {missing} in {DEFAULT_DIR}; "
                         f"train them with `{TRAIN_COMMAND}`")
    return LearnedSubPolicy(DEFAULT_DIR, greedy=greedy, seed=seed)
