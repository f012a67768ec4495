"""Learned sub-policies μ(θ): per-target actor-critics behind the SubPolicy interface.

A sub-policy has ``reset(target)`` (a new run towards a room type, or the
untyped ``indoor`` node; resets the LSTM state) and ``act(timestep) -> int``.
:class:`LearnedSubPolicy` holds one network per target, loaded from
``<folder>/<target>.pt`` as written by ``python -m leaps_mj.train policy``,
or one network shared by the targets, ``<folder>/shared.pt`` (``--shared
true``), which reads the one-hot of the node it heads for.
:func:`load_default` loads the
checkpoints shipped with the package (the ``cpu`` preset, 40x30 frames); they
act on 40x30 environments or on frames of an integer multiple of that size
(120x90), which they subsample. :func:`load_augmented` loads the shipped
semantic-augmented policies μ_s (same preset, trained with
``--use-semantic true``): the same class, whose networks also read the
observation's room-type bits and the target one-hot.
"""

from __future__ import annotations

import os
import pathlib
from typing import Sequence

import numpy as np
import torch

from leaps_mj.environment import mapping, render
from leaps_mj.learning import checkpoints, nets
from leaps_mj.world import rooms

#: File name (without ``.pt``) of one network shared by every graph node.
SHARED = "shared"
#: Folder of the shipped checkpoints (cpu preset).
DEFAULT_DIR = rooms.DATA_DIR / "policies" / "cpu"
#: The commands that train them: the cpu preset (108 k samples a target), then 72 k more from there with
#: starts up to 13 m from the first iteration (session 5; docs/training.md).
TRAIN_COMMAND = ("python -m leaps_mj.train policy --preset cpu --target all --out runs/policy_cpu && "
                 "python -m leaps_mj.train policy --preset cpu --target all --init-from runs/policy_cpu "
                 "--start-distance 13 --total-steps 72000 --out runs/policy_cpu_cont && "
                 f"cp runs/policy_cpu_cont/*.pt {DEFAULT_DIR}/")
#: Folder of the shipped semantic-augmented policies μ_s (cpu preset, the 8 room types).
AUGMENTED_DIR = DEFAULT_DIR.parent / "aug_cpu"
#: The commands that train them: the sub-policies' recipe (108 k samples a target, then 72 k more with
#: starts up to 13 m from the first iteration; session 7).
AUGMENTED_TRAIN_COMMAND = ("python -m leaps_mj.train policy --preset cpu --use-semantic true --target all "
                           "--out runs/policy_aug_cpu && "
                           "python -m leaps_mj.train policy --preset cpu --use-semantic true --target all "
                           "--init-from runs/policy_aug_cpu --start-distance 13 --total-steps 72000 "
                           f"--out runs/policy_aug_cpu_cont && cp runs/policy_aug_cpu_cont/*.pt {AUGMENTED_DIR}/")


class LearnedSubPolicy:
    """Per-target CNN+LSTM policies acting on segmentation + depth.

    Networks trained with ``use_semantic`` (μ_s) also get the observation's
    ``semantic`` bits and the one-hot of the target given to :meth:`reset`
    (the target they were trained for), so they act in any environment
    whatever its own target. A shared network (``target_input``) gets the
    one-hot of the graph node given to :meth:`reset`; a ``prev_action``
    network its own previous action in this run (none after :meth:`reset`);
    a ``map_input`` network the egocentric map this run's frames and poses
    build (a new map at each :meth:`reset`), as in training.

    Args:
      folder: Folder with one ``<target>.pt`` checkpoint per target, or a
        ``shared.pt`` serving every target without its own file.
      targets: Targets to load (default: the 8 room types and ``indoor``).
      greedy: Take the most likely action instead of sampling one.
      seed: Seed of the action sampling.
      temperature: Actions are sampled from softmax(logits / temperature):
        1 is the trained distribution, below 1 sharper (towards greedy).
      width, height: If given, the resolution the checkpoints must have.
      use_semantic: Whether the checkpoints must be μ_s networks (True) or
        pixel-only sub-policies (False).

    Attributes:
      width, height: Frame resolution the networks take (make the
        environment with these).
      targets: The loaded room types.

    Raises:
      ValueError: if a checkpoint is missing, unreadable, of another
        resolution than asked or of the other kind (``use_semantic``), or
        the checkpoints disagree on resolution.
    """

    def __init__(self, folder: str | os.PathLike, targets: Sequence[str] = rooms.GRAPH_NODES,
                 greedy: bool = False, seed: int = 0, width: int | None = None, height: int | None = None,
                 use_semantic: bool = False, temperature: float = 1.0):
        folder = pathlib.Path(folder)
        if not temperature > 0:
            raise ValueError(f"temperature {temperature!r}: expected a positive number (greedy=True for argmax)")
        if not targets:
            raise ValueError("targets is empty: expected at least one room type")
        self.nets: dict[str, nets.ActorCritic] = {}
        self.metadata: dict[str, dict] = {}
        loaded: dict[pathlib.Path, tuple] = {}
        for target in targets:
            rooms.room_index(target)
            path = checkpoint_path(folder, target)
            if path not in loaded:
                loaded[path] = checkpoints.load_policy(path, width, height)
            model, config, extra = loaded[path]
            if not isinstance(model, nets.ActorCritic) or config.use_semantic != use_semantic:
                kind = "semantic-augmented policy (μ_s)" if use_semantic else "pixel-only sub-policy"
                raise ValueError(f"{path} is not a {kind} ({type(model).__name__}, "
                                 f"use_semantic={getattr(config, 'use_semantic', None)})")
            if config.target_input and target not in extra.get("targets", rooms.GRAPH_NODES):
                raise ValueError(f"{path} is shared by {extra['targets']}, not trained for {target!r}")
            width, height = config.width, config.height
            self.nets[target] = model
            self.metadata[target] = extra
        self.width, self.height = width, height
        self.targets = tuple(targets)
        self.use_semantic = use_semantic
        self.greedy = greedy
        self.temperature = float(temperature)
        self._generator = torch.Generator().manual_seed(seed)
        self._net: nets.ActorCritic | None = None
        self._state = None
        self._target_onehot = None

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
        self._target_onehot = torch.as_tensor(rooms.target_onehot(target), dtype=torch.float32)[None]
        self._node_onehot = torch.nn.functional.one_hot(torch.tensor([rooms.room_index(target)]),
                                                        len(rooms.GRAPH_NODES)).float()
        self._prev_action = -1
        self._mapper = (mapping.EgoMapper(target, self.width, self.height) if self._net.config.map_input
                        else None)

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
        frames = {k: render.subsample(obs[k], self.width, self.height) for k in ("segmentation", "depth")}
        x = nets.ActorCritic.preprocess({k: v[None] for k, v in frames.items()})
        if self._mapper is not None:
            egomap = self._mapper.update(frames["segmentation"], frames["depth"], obs["pose"])
            x["egomap"] = torch.as_tensor(egomap[None], dtype=torch.float32)
        if self.use_semantic:
            x["semantic"] = torch.as_tensor(np.asarray(obs["semantic"], np.float32)[None])
            x["target"] = self._target_onehot
        if self._net.config.target_input:
            x["node"] = self._node_onehot
        if self._net.config.prev_action:
            x["prev_action"] = torch.tensor([self._prev_action])
        logits, _, self._state = self._net(x, self._state)
        if self.greedy:
            self._prev_action = int(logits.argmax(-1))
        else:
            probs = torch.softmax(logits[0] / self.temperature, -1)
            self._prev_action = int(torch.multinomial(probs, 1, generator=self._generator))
        return self._prev_action


def checkpoint_path(folder: str | os.PathLike, target: str) -> pathlib.Path:
    """The checkpoint serving ``target`` in a folder: ``<target>.pt``, else ``shared.pt``, else the
    (missing) ``<target>.pt``, which loading then names."""
    folder = pathlib.Path(folder)
    own = folder / f"{target}.pt"
    shared = folder / f"{SHARED}.pt"
    return shared if not own.is_file() and shared.is_file() else own


def folder_targets(folder: str | os.PathLike) -> tuple[str, ...]:
    """The graph nodes a folder of checkpoints serves (own files, or all of a shared network's targets)."""
    folder = pathlib.Path(folder)
    shared = folder / f"{SHARED}.pt"
    served = set(checkpoints.load_policy(shared)[2].get("targets", rooms.GRAPH_NODES)) if shared.is_file() else set()
    return tuple(t for t in rooms.GRAPH_NODES if (folder / f"{t}.pt").is_file() or t in served)


def _load_shipped(folder: pathlib.Path, targets: Sequence[str], command: str, use_semantic: bool,
                  greedy: bool, seed: int, temperature: float = 1.0) -> LearnedSubPolicy:
    missing = [t for t in targets if not checkpoint_path(folder, t).is_file()]
    if missing:
        raise ValueError(f"no shipped checkpoints for {missing} in {folder}; train them with `{command}`")
    return LearnedSubPolicy(folder, targets, greedy=greedy, seed=seed, use_semantic=use_semantic,
                            temperature=temperature)


def load_default(greedy: bool = False, seed: int = 0, temperature: float = 1.0) -> LearnedSubPolicy:
    """The shipped sub-policies (cpu preset, 40x30) for the 8 room types and ``indoor``.

    Raises:
      ValueError: if a shipped checkpoint is missing, naming the command that trains them.
    """
    return _load_shipped(DEFAULT_DIR, rooms.GRAPH_NODES, TRAIN_COMMAND, False, greedy, seed, temperature)


def load_augmented(greedy: bool = False, seed: int = 0) -> LearnedSubPolicy:
    """The shipped semantic-augmented policies μ_s (cpu preset, 40x30) for the 8 room types.

    Raises:
      ValueError: if a shipped checkpoint is missing, naming the command that trains them.
    """
    return _load_shipped(AUGMENTED_DIR, rooms.ROOM_TYPES, AUGMENTED_TRAIN_COMMAND, True, greedy, seed)
