"""Trains the sub-policies μ(θ), one network per target or one shared: DAgger warm start, A2C, or both.

``python -m leaps_mj.train policy --target kitchen|...|all --preset tiny|cpu|hop|paper --out DIR``

With ``--use-semantic true`` the same recipe trains the semantic-augmented
policy μ_s of the paper's baselines: the network also reads the room-type
bits and the target one-hot (``leaps_mj.learning.policies.load_augmented``).

One :class:`~leaps_mj.learning.nets.ActorCritic` per target — the 8 room types and
the untyped ``indoor`` node (hallways, for LEAPS's hallway hops) — on
segmentation + depth frames, or with ``--shared true`` one network for all
the targets that reads the node's one-hot (``<out>/shared.pt``). Options of
the network and its losses: ``--aux-coef`` (auxiliary heads on free
simulator labels), ``--prev-action true`` (the previous action as input).
Three methods:

* ``a2c`` — the paper's synchronous advantage actor-critic: ``t_max``-step
  unrolls of ``num_envs`` environments in worker processes, n-step returns
  with γ = 0.97, entropy bonus 0.1, logits L2 0.01, advantage normalisation,
  Adam (lr 1e-3, weight decay 1e-5), gradient clipping at 1.
* ``dagger`` — imitation of a teacher with DAgger (``--teacher``:
  :class:`leaps_mj.environment.expert.GeodesicExpert`, or
  :class:`leaps_mj.environment.observable_expert.ObservableExpert`, which acts
  only on what the agent has seen): the teacher labels every state the
  rollouts visit (it runs in the worker, next to its environment). The first ``learner_envs`` environments
  are always driven by the learner (on-policy data, and the success curve);
  in the others each step's action is the expert's with probability β
  (decaying linearly from 1 to ``beta_min``), else the learner's. The policy
  minimises the cross-entropy to the labels on the fresh unroll and on
  unrolls replayed from the aggregated dataset, and the value head regresses
  the n-step returns so that A2C fine-tuning starts with a trained critic.
* ``dagger+a2c`` — DAgger for ``dagger_fraction`` of the steps, then A2C.

Rollouts run in local worker processes (the default) or on Ray actors
across a cluster (``--backend ray [--ray-address ADDR] [--num-workers N]``,
:mod:`leaps_mj.learning.ray_rollouts`, docs/ray.md); both hand the same
unrolls to the same update (:mod:`leaps_mj.learning.rollouts`). The backend is
an option of the run, not of its configuration: a run may resume on either.

Training episodes are short (``horizon`` steps) and start near the target:
within ``start_distance`` geodesic metres, growing by ``distance_step`` every
``curriculum_iterations`` iterations (the paper's curriculum), with the shaped
reward of the original release.

Files under ``--out DIR`` per target::

    <target>.pt            the policy (weights + config), loadable by leaps_mj.learning.policies
    <target>/state.pt      resumable training state (weights, optimizer, counters)
    <target>/progress.csv  one row per iteration (same scalars as TensorBoard)
    <target>/events.*      TensorBoard: charts/..., losses/..., hyper-parameters once

and ``training_curves.png`` once every target of the run is done. Re-running
the same command resumes from ``state.pt`` (after a kill, too) and refuses a
different configuration; the DAgger replay buffer is not checkpointed (it
refills within ``buffer_steps`` samples).
"""

from __future__ import annotations

import argparse
import collections
import contextlib
import dataclasses
import os
import pathlib
import sys
import time
from typing import Any, Sequence

import numpy as np
import torch

from leaps_mj.learning import backend_options, checkpoints, nets, policies, rollouts
from leaps_mj.learning import trainer as trainer_lib
from leaps_mj.learning.losses import a2c_loss, aux_loss, bc_loss, masked_mean
from leaps_mj.learning.policy_config import PRESETS, TrainConfig
from leaps_mj.learning.policy_eval import evaluate, plot_curves
from leaps_mj.learning.rollouts import EpisodeStats, Unroll
from leaps_mj.world import rooms

#: The name of a shared run's one network (``--shared true``): ``<out>/shared.pt``.
SHARED = policies.SHARED

class Trainer(trainer_lib.Trainer):
    """Trains (or resumes) the policy of one target; see the module docstring.

    Args:
      config: The run's configuration.
      target: Target room type, or :data:`SHARED` for the one network of a
        ``config.shared`` run (then ``targets`` are its targets).
      out: Output folder of the run (shared by the targets).
      device: Torch device of the network.
      progress: Show a tqdm progress bar.
      targets: The targets of a shared network (default: the 9 graph nodes).
      backend: Where rollouts run, "local" or "ray" (:mod:`leaps_mj.learning.rollouts`).
      num_workers: Ray rollout actors (default: one per cluster CPU, at most ``num_envs``).
      ray_address: The Ray cluster's address (default: a local instance).
    """

    csv_fields = ("iteration", "global_step", "phase", "SPS", "beta", "start_distance", "success_rate",
                  "episode_return", "mixed_success_rate", "mixed_episode_return", "episodes",
                  "bc_cross_entropy", "bc_accuracy", "expert_agreement", "policy_loss", "value_loss", "entropy",
                  "logits_l2", "grad_norm", "aux_loss", "aux_view_accuracy", "aux_distance_error",
                  "act_forward_seconds", "update_forward_seconds",
                  "update_backward_seconds", "env_wait_seconds", "worker_physics_seconds", "worker_render_seconds",
                  "worker_expert_seconds")
    loss_keys = frozenset({"policy_loss", "value_loss", "entropy", "logits_l2", "bc_cross_entropy", "bc_accuracy",
                           "grad_norm", "expert_agreement", "aux_loss", "aux_view_accuracy", "aux_distance_error"})

    def __init__(self, config: TrainConfig, target: str, out: str | os.PathLike, device: str = "cpu",
                 progress: bool = True, targets: Sequence[str] = rooms.GRAPH_NODES, backend: str = "local",
                 num_workers: int | None = None, ray_address: str | None = None):
        backend_options.check_backend(backend, num_workers, ray_address, config.num_envs)
        if (target == SHARED) != config.shared:
            raise ValueError(f"target {target!r} with shared={config.shared}: a shared run trains target "
                             f"{SHARED!r}, a per-target run one of {list(rooms.GRAPH_NODES)}")
        if config.shared:
            for t in targets:
                rooms.room_index(t)
        else:
            rooms.room_index(target)
        super().__init__(config, pathlib.Path(out) / target, config.iterations, config.checkpoint_every,
                         progress=progress, desc=f"{target} {config.method}")
        self.target = target
        self.targets = tuple(targets) if config.shared else (target,)
        self.backend, self.num_workers, self.ray_address = backend, num_workers, ray_address
        # Seeds and house shards are per network: the shared one takes the index after the nodes'.
        self.index = len(rooms.GRAPH_NODES) if config.shared else rooms.room_index(target)
        self.run_dir = pathlib.Path(out)
        self.policy_path = self.run_dir / f"{target}.pt"
        self.device = torch.device(device)
        self.global_step = 0
        self.eval: dict | None = None
        torch.manual_seed(config.seed * 1000 + self.index)
        self.model = nets.ActorCritic(config.policy_config())
        self.optimizer = torch.optim.Adam(self.model.parameters(), lr=config.lr, weight_decay=config.weight_decay)
        if not self.resume(config.width, config.height) and config.init_from:
            self._warm_start(config.init_from)
        self.model.to(self.device).train()
        self.buffer: collections.deque[Unroll] = collections.deque(
            maxlen=max(1, config.buffer_steps // config.batch))

    def _warm_start(self, path: str) -> None:
        """Starts a new run from the weights of the policy checkpoint ``path`` (``config.init_from``).

        A folder stands for its checkpoint of this run's network (``<target>.pt``,
        else ``shared.pt``), so one option warm-starts every target of a per-target run.

        Raises:
          ValueError: naming the file, if it is not a policy checkpoint of this run's network.
        """
        if pathlib.Path(path).is_dir():
            path = policies.checkpoint_path(path, self.target)
        model, config, _ = checkpoints.load_policy(path, self.config.width, self.config.height)
        if config != self.model.config:
            raise ValueError(f"init_from {path}: holds a network {config}, expected this run's {self.model.config}")
        self.model.load_state_dict(model.state_dict())

    # -- what the skeleton checkpoints and ships -----------------------------------------------
    def state(self) -> dict[str, Any]:
        return {"target": self.target, "targets": list(self.targets), "method": self.config.method,
                "global_step": self.global_step, "eval": self.eval}

    def load_state(self, extra: dict[str, Any]) -> None:
        if extra["target"] != self.target:
            raise ValueError(f"{self.state_path} holds a run for target {extra['target']!r}, not {self.target!r}; "
                             "use another --out")
        if list(extra.get("targets", self.targets)) != list(self.targets):
            raise ValueError(f"{self.state_path} holds a run for targets {extra['targets']}, not "
                             f"{list(self.targets)}; use another --out")
        self.global_step, self.eval = extra["global_step"], extra.get("eval")

    def publish(self, extra: dict[str, Any]) -> None:
        checkpoints.save_checkpoint(self.policy_path, self.model, self.model.config, extra)

    def hyperparameters(self) -> dict[str, Any]:
        return {**dataclasses.asdict(self.config), "target": self.target}

    def log_step(self, row: dict[str, Any]) -> int:
        return self.global_step

    def postfix(self, row: dict[str, Any]) -> dict[str, str]:
        return {"sps": f"{row['SPS']:.0f}", "success": f"{row.get('success_rate', 0):.2f}",
                "beta": f"{row['beta']:.2f}"}

    # -- training --------------------------------------------------------------------------
    @contextlib.contextmanager
    def session(self):
        """The rollout backend and the episode statistics of one ``train`` call."""
        c = self.config
        if self.backend == "ray":
            from leaps_mj.learning import ray_rollouts

            source = ray_rollouts.RayRollouts(c, self.target, self.targets, self.index, self.iteration,
                                              self.num_workers, self.ray_address)
        else:
            source = rollouts.LocalRollouts(
                c, rollouts.env_kwargs(c, self.target, self.targets, self.iteration, self.run_dir),
                rollouts.env_seed(c, self.index, self.iteration), self.iteration)
        with source as self._rollouts:
            self._stats = EpisodeStats(c.num_envs)
            yield

    def iterate(self) -> dict[str, Any]:
        c = self.config
        t0 = time.perf_counter()
        rng = np.random.default_rng([c.seed, self.index, self.iteration])
        beta = c.beta_at(self.iteration)
        unroll, batch, rollout_times = self._rollouts.collect(self.model, self.iteration, beta, rng, self._stats)
        scalars = self._update(unroll, batch, rng)
        self.global_step += c.batch
        phase = "dagger" if self.iteration + 1 <= c.dagger_iterations and c.method != "a2c" else "a2c"
        return {"global_step": self.global_step, "phase": phase, **scalars, **self._stats.summary(), "beta": beta,
                "start_distance": c.start_distance_at(self.iteration), "SPS": c.batch / (time.perf_counter() - t0),
                "episodes": self._stats.finished, **rollout_times}

    def _elapsed(self, since: float) -> float:
        """Seconds since ``since``, after the device's queued work is done."""
        return rollouts.elapsed(self.device, since)

    def _unroll_forward(self, unroll: Unroll):
        """The network over an unroll: logits, values and, with auxiliary heads, their loss (else None)."""
        t0 = time.perf_counter()
        obs, first, state = unroll.tensors(self.device)
        out = self.model.unroll(obs, state, first)
        aux = None
        if self.config.aux_coef > 0:
            aux = aux_loss(self.model.aux_outputs(out), unroll.aux_tensors(self.device),
                           torch.as_tensor(unroll.valid, device=self.device))
        self._times["update_forward_seconds"] += self._elapsed(t0)
        return out["logits"], out["values"], aux

    def _step(self, loss: torch.Tensor) -> float:
        t0 = time.perf_counter()
        self.optimizer.zero_grad()
        loss.backward()
        norm = torch.nn.utils.clip_grad_norm_(self.model.parameters(), self.config.max_grad_norm)
        self.optimizer.step()
        self._times["update_backward_seconds"] += self._elapsed(t0)
        return norm.item()

    def _with_aux(self, loss: torch.Tensor, aux, out: dict | None = None) -> torch.Tensor:
        """``loss`` plus the weighted auxiliary loss (when there is one), logging its scalars into ``out``."""
        if aux is None:
            return loss
        if out is not None:
            out.update(aux[1])
        return loss + self.config.aux_coef * aux[0]

    def _update(self, unroll: Unroll, batch: dict, rng: np.random.Generator) -> dict[str, float]:
        """One update on the fresh unroll (+ replayed DAgger updates); returns log scalars."""
        c = self.config
        self._times = collections.Counter()
        dev = self.device
        valid = torch.as_tensor(unroll.valid, device=dev)
        returns = torch.as_tensor(batch["returns"], device=dev)
        logits, values, aux = self._unroll_forward(unroll)
        out = {}
        if self.iteration < c.dagger_iterations:
            labels = torch.as_tensor(unroll.labels, device=dev)
            ce, out["bc_accuracy"] = bc_loss(logits, labels, valid)
            value_loss = 0.5 * masked_mean((returns - values) ** 2, valid)
            out["grad_norm"] = self._step(self._with_aux(ce + c.value_coef * value_loss, aux, out))
            out["bc_cross_entropy"], out["value_loss"] = ce.item(), value_loss.item()
            self.buffer.append(unroll)
            for _ in range(c.replay):
                old = self.buffer[int(rng.integers(len(self.buffer)))]
                old_logits, _, old_aux = self._unroll_forward(old)
                ce, _ = bc_loss(old_logits, torch.as_tensor(old.labels, device=dev),
                                torch.as_tensor(old.valid, device=dev))
                self._step(self._with_aux(ce, old_aux))
        else:
            actions = torch.as_tensor(batch["actions"], device=dev)
            loss, out = a2c_loss(logits, values, actions, returns, valid, c)
            if (unroll.labels >= 0).any():
                ce, out["expert_agreement"] = bc_loss(logits, torch.as_tensor(unroll.labels, device=dev), valid)
                out["bc_cross_entropy"] = ce.item()
                if c.bc_coef > 0:
                    loss = loss + c.bc_coef * ce
            out["grad_norm"] = self._step(self._with_aux(loss, aux, out))
        return {**out, **self._times}


# -- a whole target ----------------------------------------------------------------------------


def run_target(config: TrainConfig, target: str, out: str | os.PathLike, device: str = "cpu",
               progress: bool = True, stop_after: int | None = None,
               targets: Sequence[str] = rooms.GRAPH_NODES, **rollout_options) -> dict | None:
    """Trains one network to completion (resuming) and evaluates it once.

    Args:
      target: The target of a per-target run, :data:`SHARED` for a shared one.
      targets: The targets of a shared network.
      **rollout_options: ``backend``, ``num_workers``, ``ray_address`` of :class:`Trainer`.

    Returns:
      The evaluation results, or None if ``stop_after`` ended the call early.
    """
    trainer = Trainer(config, target, out, device=device, progress=progress, targets=targets, **rollout_options)
    trainer.train(stop_after)
    if not trainer.finished:
        return None
    if trainer.eval is None:
        modes = {mode: policies.LearnedSubPolicy(out, targets=trainer.targets, greedy=mode == "greedy",
                                                   seed=config.seed, use_semantic=config.use_semantic)
                 for mode in ("sampled", "greedy")}
        seed = config.seed + 7919 * (1 + trainer.index)
        trainer.eval = {f"{split}/{mode}": result for split in ("train", "valid")
                        for mode, result in evaluate(modes, trainer.targets, config, split, seed).items()}
        trainer.save()
    return trainer.eval


# -- command line --------------------------------------------------------------------------------


def parse_targets(text: str, use_semantic: bool) -> tuple[str, ...]:
    """The targets of ``--target``: "all" or comma-separated names.

    "all" is the 8 room types and ``indoor`` for sub-policies, the 8 room
    types for μ_s (an agent runs μ_s towards its final target only, never
    towards a hallway).

    Raises:
      ValueError: for an unknown or repeated name.
    """
    if text == "all":
        return rooms.ROOM_TYPES if use_semantic else rooms.GRAPH_NODES
    targets = tuple(t.strip() for t in text.split(","))
    for target in targets:
        if target not in rooms.GRAPH_NODES:
            raise ValueError(f"target {target!r}: expected 'all' or comma-separated names from "
                             f"{list(rooms.GRAPH_NODES)}")
    if len(set(targets)) != len(targets):
        raise ValueError(f"target {text!r} names a room type twice")
    return targets


def build_parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(
        prog="python -m leaps_mj.train policy", description=__doc__.split("\n\n")[0],
        formatter_class=argparse.ArgumentDefaultsHelpFormatter)
    parser.add_argument("--preset", choices=sorted(PRESETS), default="cpu", help="base configuration")
    parser.add_argument("--target", default="all",
                        help=f"'all' or comma-separated names from {list(rooms.GRAPH_NODES)}")
    parser.add_argument("--out", default="runs/policy", help="output folder (resumed if it holds a run)")
    parser.add_argument("--device", default="cpu", help="torch device of the network (cpu, cuda)")
    parser.add_argument("--threads", type=int, default=1,
                        help="torch CPU threads of the learner (the environment workers use the other cores)")
    parser.add_argument("--stop-after", type=int, default=None,
                        help="stop each target after this many more iterations (checkpointed; rerun resumes)")
    parser.add_argument("--no-progress", action="store_true", help="no progress bar")
    backend_options.add_backend_arguments(parser, "rollouts", "each holding num_envs / N environments (default: one per "
                                   "cluster CPU, at most num_envs)")
    trainer_lib.add_config_arguments(parser, TrainConfig)
    return parser


def main(argv: Sequence[str] | None = None) -> int:
    args = build_parser().parse_args(argv)
    config = dataclasses.replace(PRESETS[args.preset], **trainer_lib.config_overrides(args, TrainConfig))
    targets = parse_targets(args.target, config.use_semantic)
    if args.stop_after is not None and args.stop_after < 1:
        raise ValueError(f"--stop-after {args.stop_after}: expected a positive integer")
    if args.threads < 1:
        raise ValueError(f"--threads {args.threads}: expected a positive integer")
    torch.set_num_threads(args.threads)
    out = pathlib.Path(args.out)
    results = {}
    for target in ((SHARED,) if config.shared else targets):
        results[target] = run_target(config, target, out, args.device, not args.no_progress, args.stop_after,
                                     targets=targets, backend=args.backend, num_workers=args.num_workers,
                                     ray_address=args.ray_address)
    print(f"{'target':12} {'train':>8} {'valid':>8} {'valid greedy':>13}  (success on sampled episodes)")
    for target, res in results.items():
        if res is None:
            print(f"{target:12} {'(stopped early; rerun to resume)':>31}")
        else:
            print(f"{target:12} {res['train/sampled']['success_rate']:8.2f} {res['valid/sampled']['success_rate']:8.2f}"
                  f" {res['valid/greedy']['success_rate']:13.2f}")
    if all(r is not None for r in results.values()):
        plot_curves(out, list(results), out / "training_curves.png")
        print(f"wrote {out / 'training_curves.png'}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
