"""Trains the per-target sub-policies μ(θ): DAgger warm start, A2C, or both.

``python -m leaps_mj.train policy --target kitchen|...|all --preset tiny|cpu|paper --out DIR``

With ``--use-semantic true`` the same recipe trains the semantic-augmented
policy μ_s of the paper's baselines: the network also reads the room-type
bits and the target one-hot (``leaps_mj.policies.load_augmented``).

One :class:`~leaps_mj.nets.ActorCritic` per target — the 8 room types and
the untyped ``indoor`` node (hallways, for LEAPS's hallway hops) — on
segmentation + depth frames. Three methods:

* ``a2c`` — the paper's synchronous advantage actor-critic: ``t_max``-step
  unrolls of ``num_envs`` environments in worker processes, n-step returns
  with γ = 0.97, entropy bonus 0.1, logits L2 0.01, advantage normalisation,
  Adam (lr 1e-3, weight decay 1e-5), gradient clipping at 1.
* ``dagger`` — imitation of :class:`leaps_mj.expert.GeodesicExpert` with
  DAgger: the expert labels every state the rollouts visit (it runs in the
  worker, next to its environment). The first ``learner_envs`` environments
  are always driven by the learner (on-policy data, and the success curve);
  in the others each step's action is the expert's with probability β
  (decaying linearly from 1 to ``beta_min``), else the learner's. The policy
  minimises the cross-entropy to the labels on the fresh unroll and on
  unrolls replayed from the aggregated dataset, and the value head regresses
  the n-step returns so that A2C fine-tuning starts with a trained critic.
* ``dagger+a2c`` — DAgger for ``dagger_fraction`` of the steps, then A2C.

Training episodes are short (``horizon`` steps) and start near the target:
within ``start_distance`` geodesic metres, growing by ``distance_step`` every
``curriculum_iterations`` iterations (the paper's curriculum), with the shaped
reward of the original release.

Files under ``--out DIR`` per target::

    <target>.pt            the policy (weights + config), loadable by leaps_mj.policies
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
import csv
import dataclasses
import functools
import io
import math
import os
import pathlib
import sys
import time
from typing import Any, Sequence

import numpy as np
import torch
import torch.nn.functional as F
import tqdm

import leaps_mj
from leaps_mj import dataset as dataset_lib
from leaps_mj import houses, nets, rooms, vector
from leaps_mj.expert import GeodesicExpert

METHODS = ("a2c", "dagger", "dagger+a2c")


@dataclasses.dataclass(frozen=True)
class TrainConfig:
    """Everything that defines a sub-policy training run (one per preset).

    Attributes:
      dataset: House dataset name or folder (its ``train`` split is used).
      num_houses: Train on the first this many houses of the split that have
        a room of the target type (0: all of them), sharded over the workers.
      width, height: Frame resolution of the environment and the network.
      conv_channels, kernel, hidden, lstm, seg_embed: Network widths
        (:class:`leaps_mj.nets.PolicyConfig`).
      use_semantic: Train the semantic-augmented policy μ_s: the network
        also reads the room-type bits and the target one-hot.
      method: "a2c", "dagger" or "dagger+a2c".
      total_steps: Environment steps per target (all environments together).
      dagger_fraction: Share of the iterations spent on DAgger in "dagger+a2c".
      beta_fraction: Share of the DAgger iterations over which β, the
        probability that the expert takes a step of a mixed environment,
        decays linearly from 1 to ``beta_min``.
      beta_min: Final β of the DAgger phase. Above 0, mixed environments keep
        following the expert with the learner's deviations (DART-like): the
        learner's own early rollouts mostly turn on the spot, and labels from
        them alone teach it to keep turning.
      learner_envs: Environments always driven by the learner alone.
      replay: Extra DAgger updates per iteration, each on one unroll drawn
        from the aggregated dataset.
      buffer_steps: Samples kept in the aggregated dataset (oldest dropped).
      num_envs: Environments (worker processes) stepped together.
      t_max: Unroll length of one update.
      gamma: Discount of the n-step returns.
      lr: Adam learning rate.
      weight_decay: Adam weight decay.
      entropy: Entropy bonus coefficient (A2C).
      value_coef: Value-loss coefficient.
      logits_l2: Coefficient of the mean squared logits penalty.
      max_grad_norm: Gradient clipping norm.
      normalize_advantages: Normalise advantages over each unroll (A2C).
      horizon: Steps of a training episode.
      start_distance: Initial bound on the start's geodesic distance (metres).
      distance_step: Metres added to the bound every ``curriculum_iterations``.
      curriculum_iterations: Iterations per curriculum stage.
      max_distance: Largest bound the curriculum reaches (metres).
      checkpoint_every: Iterations between checkpoints.
      eval_episodes: Episodes of the final evaluation, per split.
      eval_horizon: Steps of an evaluation episode.
      seed: Seed of every random draw of the run.
    """

    dataset: str = "roomnav-v1"
    num_houses: int = 0
    width: int = 120
    height: int = 90
    conv_channels: tuple[int, ...] = (64, 64, 128, 128)
    kernel: int = 5
    hidden: int = 256
    lstm: int = 256
    seg_embed: int = 8
    use_semantic: bool = False
    method: str = "a2c"
    total_steps: int = 20_000_000
    dagger_fraction: float = 0.7
    beta_fraction: float = 0.5
    beta_min: float = 0.0
    learner_envs: int = 1
    replay: int = 2
    buffer_steps: int = 50_000
    num_envs: int = 64
    t_max: int = 30
    gamma: float = 0.97
    lr: float = 1e-3
    weight_decay: float = 1e-5
    entropy: float = 0.1
    value_coef: float = 0.5
    logits_l2: float = 0.01
    max_grad_norm: float = 1.0
    normalize_advantages: bool = True
    horizon: int = 60
    start_distance: float = 6.0
    distance_step: float = 3.0
    curriculum_iterations: int = 10_000
    max_distance: float = 30.0
    checkpoint_every: int = 100
    eval_episodes: int = 20
    eval_horizon: int = 100
    seed: int = 0

    def __post_init__(self):
        object.__setattr__(self, "conv_channels", tuple(self.conv_channels))
        if self.method not in METHODS:
            raise ValueError(f"method {self.method!r}: expected one of {list(METHODS)}")
        for name in ("total_steps", "num_envs", "t_max", "horizon", "curriculum_iterations",
                     "checkpoint_every", "eval_episodes", "eval_horizon", "buffer_steps"):
            value = getattr(self, name)
            if isinstance(value, bool) or not isinstance(value, int) or value < 1:
                raise ValueError(f"{name} {value!r}: expected a positive integer")
        for name in ("num_houses", "replay", "seed"):
            value = getattr(self, name)
            if isinstance(value, bool) or not isinstance(value, int) or value < 0:
                raise ValueError(f"{name} {value!r}: expected an integer >= 0")
        for name in ("dagger_fraction", "beta_fraction", "beta_min", "gamma"):
            if not 0.0 <= getattr(self, name) <= 1.0:
                raise ValueError(f"{name} {getattr(self, name)!r}: expected a value in [0, 1]")
        for name in ("lr", "start_distance", "max_distance", "max_grad_norm"):
            if not getattr(self, name) > 0:
                raise ValueError(f"{name} {getattr(self, name)!r}: expected a positive number")
        for name in ("weight_decay", "entropy", "value_coef", "logits_l2", "distance_step"):
            if not getattr(self, name) >= 0:
                raise ValueError(f"{name} {getattr(self, name)!r}: expected a number >= 0")
        if not isinstance(self.learner_envs, int) or not 0 <= self.learner_envs <= self.num_envs:
            raise ValueError(f"learner_envs {self.learner_envs!r}: expected an integer in [0, num_envs]")
        self.policy_config()  # validates the network fields

    def policy_config(self) -> nets.PolicyConfig:
        """The network architecture of this run."""
        return nets.PolicyConfig(width=self.width, height=self.height, conv_channels=self.conv_channels,
                                 kernel=self.kernel, hidden=self.hidden, lstm=self.lstm, seg_embed=self.seg_embed,
                                 use_semantic=self.use_semantic)

    @property
    def batch(self) -> int:
        """Samples per iteration."""
        return self.num_envs * self.t_max

    @property
    def iterations(self) -> int:
        """Iterations of the whole run."""
        return math.ceil(self.total_steps / self.batch)

    @property
    def dagger_iterations(self) -> int:
        """Iterations of the DAgger phase (the first ones)."""
        return {"a2c": 0, "dagger": self.iterations,
                "dagger+a2c": round(self.dagger_fraction * self.iterations)}[self.method]

    def start_distance_at(self, iteration: int) -> float:
        """The curriculum's bound on start distances (metres) at an iteration."""
        stage = iteration // self.curriculum_iterations
        return min(self.max_distance, self.start_distance + self.distance_step * stage)

    def beta_at(self, iteration: int) -> float:
        """Probability that the expert takes a step of a mixed environment at an iteration."""
        if iteration >= self.dagger_iterations:
            return 0.0
        decay = max(1, round(self.beta_fraction * self.dagger_iterations))
        return max(self.beta_min, 1.0 - iteration / decay)


PRESETS = {
    # Seconds: for tests and smoke runs.
    "tiny": TrainConfig(
        num_houses=4, width=24, height=18, conv_channels=(8, 8), hidden=16, lstm=16,
        method="dagger+a2c", total_steps=96, num_envs=2, t_max=8, replay=1, buffer_steps=64,
        horizon=20, start_distance=3.0, curriculum_iterations=2, checkpoint_every=2,
        eval_episodes=2, eval_horizon=10),
    # All 9 targets in about 50 minutes on 2 shared CPU cores: 40x30 frames, a
    # narrow net, 32 houses with the target (4 per worker), DAgger only.
    "cpu": TrainConfig(
        num_houses=32, width=40, height=30, conv_channels=(16, 32, 32, 32), hidden=128, lstm=64,
        method="dagger", total_steps=108_000, beta_min=0.5, learner_envs=2, replay=3, num_envs=8,
        start_distance=4.0, curriculum_iterations=90, max_distance=13.0, checkpoint_every=10),
    # The paper's setting, for a GPU or a cluster (not run on the CPU machine).
    "paper": TrainConfig(),
}


# -- worker side ---------------------------------------------------------------------------------


class TrainingEnv:
    """Worker-side wrapper of a RoomNav environment for training.

    Runs in the environment's worker process and adds to every observation:

    * ``expert_action`` (int64 scalar): the geodesic expert's action for the
      state (-1 when labelling is off), the DAgger label;
    * ``step_seconds`` (float64 (3,)): seconds this step spent in physics and
      collisions (``Task.before_step``), in rendering and the success test
      (``Task.after_step``) and in the expert — for the throughput benchmark.

    It also applies the distance curriculum: each new episode's start is
    bounded by ``config.start_distance_at(iteration)``, where the iteration is
    counted from the worker's own steps (every worker steps ``t_max`` times
    per iteration), so no extra command is needed. The bound is set by
    replacing the environment's ``config`` (``sample_episode`` reads
    ``max_start_distance`` from it), and the timings wrap the task's
    ``before_step`` / ``after_step`` on this instance.

    Args:
      env: The environment (from :func:`leaps_mj.load`).
      config: The run's :class:`TrainConfig`.
      first_iteration: Training iteration at which this worker starts.
      seed: Seed of the expert's random moves.
      label: Whether to compute expert labels.
    """

    def __init__(self, env, config: TrainConfig, first_iteration: int, seed: int, label: bool):
        self._env = env
        self._config = config
        self._steps = first_iteration * config.t_max
        self._expert = GeodesicExpert(env, seed=seed) if label else None
        self._last = True
        self._times = np.zeros(3)
        task = env.task
        task.before_step = self._timed(task.before_step, 0)
        task.after_step = self._timed(task.after_step, 1)

    def _timed(self, fn, slot):
        def timed(*args):
            t0 = time.perf_counter()
            out = fn(*args)
            self._times[slot] += time.perf_counter() - t0
            return out
        return timed

    def _augment(self, ts):
        self._last = ts.last()
        t0 = time.perf_counter()
        label = self._expert.act() if self._expert is not None and not ts.last() else -1
        self._times[2] += time.perf_counter() - t0
        obs = dict(ts.observation, expert_action=np.int64(label), step_seconds=self._times.copy())
        self._times[:] = 0.0
        return ts._replace(observation=obs)

    def reset(self):
        distance = self._config.start_distance_at(self._steps // self._config.t_max)
        if self._env.config.max_start_distance != distance:
            self._env.config = dataclasses.replace(self._env.config, max_start_distance=distance)
        return self._augment(self._env.reset())

    def step(self, action):
        self._steps += 1
        if self._last:
            return self.reset()
        return self._augment(self._env.step(action))

    def reset_to(self, spec):
        return self._augment(self._env.reset_to(spec))

    @property
    def episode(self):
        return self._env.episode

    def observation_spec(self):
        return self._env.observation_spec()

    def action_spec(self):
        return self._env.action_spec()

    def close(self):
        self._env.close()


def make_training_env(seed: int, config: TrainConfig, first_iteration: int, label: bool,
                      **env_kwargs) -> TrainingEnv:
    """A worker's :class:`TrainingEnv` (the ``make_env`` of :class:`leaps_mj.vector.VectorEnv`)."""
    return TrainingEnv(leaps_mj.load(seed=seed, **env_kwargs), config, first_iteration, seed, label)


def training_vector_env(worker_kwargs: Sequence[dict], seed: int, config: TrainConfig, first_iteration: int,
                        label: bool) -> vector.VectorEnv:
    """Worker processes serving :class:`TrainingEnv`, each with its own arguments.

    Args:
      worker_kwargs: One dict of :func:`leaps_mj.load` arguments per worker
        (its shard of the training houses: a worker keeps every house it
        visits compiled).
      seed: Worker ``i`` gets seed ``seed + i`` (environment and expert).
      config: The run's :class:`TrainConfig`.
      first_iteration: Iteration at which training (re)starts (curriculum).
      label: Whether workers compute expert labels.
    """
    make_env = functools.partial(make_training_env, config=config, first_iteration=first_iteration, label=label)
    return vector.VectorEnv(len(worker_kwargs), seed, make_env=make_env, worker_kwargs=list(worker_kwargs))


# -- returns and losses ---------------------------------------------------------------------------


def n_step_returns(rewards: np.ndarray, discounts: np.ndarray, next_values: np.ndarray,
                   bootstrap: np.ndarray) -> np.ndarray:
    """n-step returns of an unroll, bootstrapped where the unroll or episode ends.

    ``R_t = r_t + d_t * (V(s_{t+1}) if bootstrap_t else R_{t+1})``.

    Args:
      rewards: (T, B) reward of the step from s_t.
      discounts: (T, B) γ times the environment's discount of that step
        (0 after a success, γ at a horizon truncation).
      next_values: (T, B) value estimates of s_{t+1}.
      bootstrap: (T, B) bool; True where R_{t+1} is not available: at the
        last step of the unroll and where s_{t+1} ends its episode.

    Returns:
      (T, B) returns.

    Raises:
      ValueError: if the shapes differ or the last step does not bootstrap.
    """
    shapes = {a.shape for a in (rewards, discounts, next_values, bootstrap)}
    if len(shapes) != 1 or rewards.ndim != 2:
        raise ValueError(f"rewards, discounts, next_values, bootstrap must share one (T, B) shape, got {shapes}")
    if not np.all(bootstrap[-1]):
        raise ValueError("bootstrap[-1] must be all True: the unroll's last step has no R_{t+1}")
    returns = np.zeros(rewards.shape, dtype=np.float64)
    following = next_values[-1]
    for t in reversed(range(rewards.shape[0])):
        following = np.where(bootstrap[t], next_values[t], following)
        returns[t] = rewards[t] + discounts[t] * following
        following = returns[t]
    return returns


def _masked_mean(x: torch.Tensor, mask: torch.Tensor) -> torch.Tensor:
    return (x * mask).sum() / mask.sum().clamp(min=1.0)


def a2c_loss(logits: torch.Tensor, values: torch.Tensor, actions: torch.Tensor, returns: torch.Tensor,
             valid: torch.Tensor, config: TrainConfig) -> tuple[torch.Tensor, dict[str, float]]:
    """The A2C loss of an unroll (all tensors (T, B, ...); ``valid`` masks steps).

    Returns:
      (loss, scalars for logging).
    """
    dist = torch.distributions.Categorical(logits=logits)
    advantages = returns - values.detach()
    if config.normalize_advantages:
        mean = _masked_mean(advantages, valid)
        std = _masked_mean((advantages - mean) ** 2, valid).sqrt()
        advantages = (advantages - mean) / (std + 1e-8)
    policy_loss = -_masked_mean(dist.log_prob(actions) * advantages, valid)
    value_loss = 0.5 * _masked_mean((returns - values) ** 2, valid)
    entropy = _masked_mean(dist.entropy(), valid)
    logits_l2 = _masked_mean((logits ** 2).mean(-1), valid)
    loss = policy_loss + config.value_coef * value_loss - config.entropy * entropy + config.logits_l2 * logits_l2
    return loss, {"policy_loss": policy_loss.item(), "value_loss": value_loss.item(),
                  "entropy": entropy.item(), "logits_l2": logits_l2.item()}


def bc_loss(logits: torch.Tensor, labels: torch.Tensor, valid: torch.Tensor) -> tuple[torch.Tensor, float]:
    """Cross-entropy to the expert labels over valid steps, and the accuracy."""
    ce = F.cross_entropy(logits.reshape(-1, logits.shape[-1]), labels.reshape(-1).clamp(min=0),
                         reduction="none").reshape(labels.shape)
    accuracy = _masked_mean((logits.argmax(-1) == labels).float(), valid).item()
    return _masked_mean(ce, valid), accuracy


# -- rollouts ------------------------------------------------------------------------------------


@dataclasses.dataclass
class Unroll:
    """``t_max`` steps of ``num_envs`` environments, as stored for updates.

    Segmentation is uint8, depth float16 (the aggregated dataset keeps many).
    """

    segmentation: np.ndarray  # (T, B, H, W) uint8
    depth: np.ndarray  # (T, B, H, W) float16
    first: np.ndarray  # (T, B) float32, 1 where an episode began
    valid: np.ndarray  # (T, B) float32, 0 at LAST observations (their action is ignored)
    labels: np.ndarray  # (T, B) int64 expert actions (-1: none)
    state: tuple[np.ndarray, np.ndarray]  # LSTM (h, c) at the unroll's start
    semantic: np.ndarray | None = None  # (T, B, K) uint8 room-type bits (μ_s only)
    target: np.ndarray | None = None  # (T, B, K) uint8 target one-hot (μ_s only)

    def tensors(self, device) -> tuple[dict, torch.Tensor, tuple[torch.Tensor, torch.Tensor]]:
        arrays = {"segmentation": self.segmentation, "depth": self.depth}
        if self.semantic is not None:
            arrays.update(semantic=self.semantic, target=self.target)
        obs = nets.ActorCritic.preprocess(arrays, device)
        first = torch.as_tensor(self.first, device=device)
        state = tuple(torch.as_tensor(s, device=device) for s in self.state)
        return obs, first, state


class EpisodeStats:
    """Outcomes of the last ``window`` episodes finished in rollouts: learner-driven or mixed."""

    def __init__(self, num_envs: int, window: int = 50):
        self.returns = np.zeros(num_envs)
        self.recent = {"learner": collections.deque(maxlen=window), "mixed": collections.deque(maxlen=window)}
        self.finished = 0

    def record(self, i: int, ts, mixed: bool) -> None:
        if ts.reward is not None:
            self.returns[i] += ts.reward
        if ts.last():
            self.recent["mixed" if mixed else "learner"].append(
                (float(ts.discount == 0.0), self.returns[i]))
            self.returns[i] = 0.0
            self.finished += 1

    def summary(self) -> dict[str, float]:
        out = {}
        for who, items in self.recent.items():
            if items:
                arr = np.array(items)
                prefix = "" if who == "learner" else "mixed_"
                out[f"{prefix}success_rate"] = float(arr[:, 0].mean())
                out[f"{prefix}episode_return"] = float(arr[:, 1].mean())
        return out


class Trainer:
    """Trains (or resumes) the policy of one target; see the module docstring.

    Args:
      config: The run's configuration.
      target: Target room type.
      out: Output folder of the run (shared by the targets).
      device: Torch device of the network.
      progress: Show a tqdm progress bar.
    """

    def __init__(self, config: TrainConfig, target: str, out: str | os.PathLike, device: str = "cpu",
                 progress: bool = True):
        rooms.room_index(target)
        self.config = config
        self.target = target
        self.out = pathlib.Path(out)
        self.dir = self.out / target
        self.state_path = self.dir / "state.pt"
        self.policy_path = self.out / f"{target}.pt"
        self.device = torch.device(device)
        self.progress = progress
        self.iteration = 0
        self.global_step = 0
        self.elapsed = 0.0
        self.eval: dict | None = None
        torch.manual_seed(config.seed * 1000 + rooms.room_index(target))
        self.model = nets.ActorCritic(config.policy_config())
        self.optimizer = torch.optim.Adam(self.model.parameters(), lr=config.lr, weight_decay=config.weight_decay)
        if self.state_path.exists():
            self._resume()
        self.model.to(self.device).train()
        self.buffer: collections.deque[Unroll] = collections.deque(
            maxlen=max(1, config.buffer_steps // config.batch))

    # -- checkpoints -----------------------------------------------------------------------
    def _resume(self) -> None:
        model, _, extra = nets.load_policy(self.state_path, self.config.width, self.config.height)
        if extra["target"] != self.target:
            raise ValueError(f"{self.state_path} holds a run for target {extra['target']!r}, not {self.target!r}; "
                             "use another --out")
        nets.check_same_config(self.state_path, extra["train_config"], self.config)
        self.model.load_state_dict(model.state_dict())
        self.optimizer.load_state_dict(extra["optimizer"])
        self.iteration, self.global_step = extra["iteration"], extra["global_step"]
        self.elapsed = extra["elapsed"]
        self.eval = extra.get("eval")

    def _extra(self) -> dict[str, Any]:
        return {"target": self.target, "method": self.config.method, "iteration": self.iteration,
                "global_step": self.global_step, "elapsed": self.elapsed,
                "train_config": dataclasses.asdict(self.config), "eval": self.eval}

    def save(self) -> None:
        """Writes the resumable state and the policy file (both atomically)."""
        model = self.model.to("cpu")
        nets.save_checkpoint(self.state_path, model, model.config,
                             {**self._extra(), "optimizer": self.optimizer.state_dict()})
        nets.save_checkpoint(self.policy_path, model, model.config, self._extra())
        self.model.to(self.device)

    @property
    def finished(self) -> bool:
        return self.iteration >= self.config.iterations

    # -- training --------------------------------------------------------------------------
    def _worker_kwargs(self) -> list[dict[str, Any]]:
        c = self.config
        shards = training_houses(c.dataset, self.target, c.num_houses, c.num_envs, self.out)
        return [dict(houses_dir=str(shard), width=c.width, height=c.height, horizon=c.horizon, reward="shaped",
                     targets=(self.target,), max_start_distance=c.start_distance_at(self.iteration))
                for shard in shards]

    def train(self, stop_after: int | None = None) -> None:
        """Runs iterations until the run is complete (or ``stop_after`` more are done)."""
        from torch.utils.tensorboard import SummaryWriter

        c = self.config
        if self.finished:
            return
        self.dir.mkdir(parents=True, exist_ok=True)
        writer = SummaryWriter(str(self.dir))
        if self.iteration == 0:
            rows = "\n".join(f"|{k}|{v}|" for k, v in dataclasses.asdict(c).items())
            writer.add_text("hyperparameters", f"|param|value|\n|-|-|\n{rows}|target|{self.target}|")
        csv_log = _CsvLog(self.dir / "progress.csv", self.iteration)
        label = c.method != "a2c"
        seed = (c.seed * 1000 + rooms.room_index(self.target)) * 100_000 + self.iteration * c.num_envs
        last = self.iteration + stop_after if stop_after is not None else c.iterations
        last = min(last, c.iterations)
        bar = tqdm.tqdm(total=c.iterations * c.batch, initial=self.global_step, unit="step",
                        desc=f"{self.target} {c.method}", disable=not self.progress, dynamic_ncols=True)
        with training_vector_env(self._worker_kwargs(), seed, c, self.iteration, label) as envs:
            timesteps = envs.reset()
            state = self.model.initial_state(c.num_envs, self.device)
            stats = EpisodeStats(c.num_envs)
            while self.iteration < last:
                t0 = time.perf_counter()
                rng = np.random.default_rng([c.seed, rooms.room_index(self.target), self.iteration])
                gen = torch.Generator(device=self.device).manual_seed(int(rng.integers(2**63)))
                beta = c.beta_at(self.iteration)
                unroll, batch, timesteps, state, rollout_times = self._rollout(
                    envs, timesteps, state, beta, rng, gen, stats)
                scalars = self._update(unroll, batch, rng)
                self.iteration += 1
                self.global_step += c.batch
                dt = time.perf_counter() - t0
                self.elapsed += dt
                scalars.update(stats.summary(), beta=beta, start_distance=c.start_distance_at(self.iteration - 1),
                               SPS=c.batch / dt, episodes=stats.finished, **rollout_times)
                self._log(writer, csv_log, scalars)
                bar.update(c.batch)
                bar.set_postfix(sps=f"{scalars['SPS']:.0f}", success=f"{scalars.get('success_rate', 0):.2f}",
                                beta=f"{beta:.2f}")
                if self.iteration % c.checkpoint_every == 0 or self.iteration == last:
                    self.save()
        bar.close()
        writer.close()

    def _rollout(self, envs, timesteps, state, beta, rng, gen, stats):
        """Collects one unroll; returns it with the A2C batch and the carried state."""
        c = self.config
        T, B = c.t_max, c.num_envs
        seg = np.zeros((T, B, c.height, c.width), np.uint8)
        depth = np.zeros((T, B, c.height, c.width), np.float16)
        keys = ("segmentation", "depth") + (("semantic", "target") if c.use_semantic else ())
        bits = {k: np.zeros((T, B, rooms.NUM_ROOM_TYPES), np.uint8) for k in keys[2:]}
        first, valid = np.zeros((T, B), np.float32), np.zeros((T, B), np.float32)
        labels, actions = np.zeros((T, B), np.int64), np.zeros((T, B), np.int64)
        rewards, discounts = np.zeros((T, B)), np.zeros((T, B))
        values, bootstrap = np.zeros((T + 1, B)), np.zeros((T, B), bool)
        start_state = tuple(s.detach().cpu().numpy() for s in state)
        times = collections.Counter()
        for t in range(T + 1):
            obs = {k: vector.stack(timesteps, k) for k in keys + ("expert_action",)}
            is_first = np.array([ts.first() for ts in timesteps], np.float32)
            f0 = time.perf_counter()
            with torch.no_grad():
                x = nets.ActorCritic.preprocess(obs, self.device)
                logits, value, new_state = self.model(x, state, torch.as_tensor(is_first, device=self.device))
                learner = torch.multinomial(torch.softmax(logits, -1), 1, generator=gen).squeeze(-1).cpu().numpy()
            times["act_forward_seconds"] += self._elapsed(f0)
            values[t] = value.cpu().numpy()
            if t == T:
                break
            state = new_state
            seg[t], depth[t], first[t], labels[t] = obs["segmentation"], obs["depth"], is_first, obs["expert_action"]
            for k, array in bits.items():
                array[t] = obs[k]
            valid[t] = [not ts.last() for ts in timesteps]
            expert = (rng.random(B) < beta) & (np.arange(B) >= c.learner_envs) & (labels[t] >= 0)
            actions[t] = np.where(expert, labels[t], learner)
            e0 = time.perf_counter()
            timesteps = envs.step([int(a) for a in actions[t]])
            times["env_wait_seconds"] += time.perf_counter() - e0
            for i, ts in enumerate(timesteps):
                stats.record(i, ts, i >= c.learner_envs and beta > 0)
                times["worker_physics_seconds"] += ts.observation["step_seconds"][0]
                times["worker_render_seconds"] += ts.observation["step_seconds"][1]
                times["worker_expert_seconds"] += ts.observation["step_seconds"][2]
                if valid[t, i]:
                    rewards[t, i] = ts.reward
                    discounts[t, i] = c.gamma * ts.discount
                bootstrap[t, i] = ts.last() or t == T - 1
        returns = n_step_returns(rewards, discounts, values[1:], bootstrap)
        unroll = Unroll(seg, depth, first, valid, labels, start_state, **bits)
        batch = {"actions": actions, "returns": returns.astype(np.float32)}
        return unroll, batch, timesteps, state, dict(times)

    def _elapsed(self, since: float) -> float:
        """Seconds since ``since``, after the device's queued work is done."""
        if self.device.type == "cuda":
            torch.cuda.synchronize(self.device)
        return time.perf_counter() - since

    def _unroll_forward(self, unroll: Unroll):
        t0 = time.perf_counter()
        obs, first, state = unroll.tensors(self.device)
        logits, values, _ = self.model.forward_sequence(obs, state, first)
        self._times["update_forward_seconds"] += self._elapsed(t0)
        return logits, values

    def _step(self, loss: torch.Tensor) -> float:
        t0 = time.perf_counter()
        self.optimizer.zero_grad()
        loss.backward()
        norm = torch.nn.utils.clip_grad_norm_(self.model.parameters(), self.config.max_grad_norm)
        self.optimizer.step()
        self._times["update_backward_seconds"] += self._elapsed(t0)
        return norm.item()

    def _update(self, unroll: Unroll, batch: dict, rng: np.random.Generator) -> dict[str, float]:
        """One update on the fresh unroll (+ replayed DAgger updates); returns log scalars."""
        c = self.config
        self._times = collections.Counter()
        dev = self.device
        valid = torch.as_tensor(unroll.valid, device=dev)
        returns = torch.as_tensor(batch["returns"], device=dev)
        logits, values = self._unroll_forward(unroll)
        out = {}
        if self.iteration < c.dagger_iterations:
            labels = torch.as_tensor(unroll.labels, device=dev)
            ce, out["bc_accuracy"] = bc_loss(logits, labels, valid)
            value_loss = 0.5 * _masked_mean((returns - values) ** 2, valid)
            out["grad_norm"] = self._step(ce + c.value_coef * value_loss)
            out["bc_cross_entropy"], out["value_loss"] = ce.item(), value_loss.item()
            self.buffer.append(unroll)
            for _ in range(c.replay):
                old = self.buffer[int(rng.integers(len(self.buffer)))]
                old_logits, _ = self._unroll_forward(old)
                ce, _ = bc_loss(old_logits, torch.as_tensor(old.labels, device=dev),
                                torch.as_tensor(old.valid, device=dev))
                self._step(ce)
        else:
            actions = torch.as_tensor(batch["actions"], device=dev)
            loss, out = a2c_loss(logits, values, actions, returns, valid, c)
            if (unroll.labels >= 0).any():
                _, out["expert_agreement"] = bc_loss(logits.detach(), torch.as_tensor(unroll.labels, device=dev),
                                                     valid)
            out["grad_norm"] = self._step(loss)
        return {**out, **self._times}

    def _log(self, writer, csv_log, scalars: dict[str, float]) -> None:
        row = {"iteration": self.iteration, "global_step": self.global_step,
               "phase": "dagger" if self.iteration <= self.config.dagger_iterations and self.config.method != "a2c"
               else "a2c"}
        for key, value in scalars.items():
            group = "losses" if key in _LOSS_KEYS else "charts"
            writer.add_scalar(f"{group}/{key}", value, self.global_step)
            row[key] = value
        csv_log.write(row)


_LOSS_KEYS = {"policy_loss", "value_loss", "entropy", "logits_l2", "bc_cross_entropy", "bc_accuracy",
              "grad_norm", "expert_agreement"}


class _CsvLog:
    """Appends rows to a CSV file (header from the first row; resumed runs append)."""

    FIELDS = ("iteration", "global_step", "phase", "SPS", "beta", "start_distance", "success_rate",
              "episode_return", "mixed_success_rate", "mixed_episode_return", "episodes",
              "bc_cross_entropy", "bc_accuracy", "expert_agreement", "policy_loss", "value_loss", "entropy",
              "logits_l2", "grad_norm", "act_forward_seconds", "update_forward_seconds", "update_backward_seconds",
              "env_wait_seconds", "worker_physics_seconds", "worker_render_seconds", "worker_expert_seconds")

    def __init__(self, path: pathlib.Path, keep_through: int):
        """Opens the log, dropping rows after iteration ``keep_through`` (not checkpointed before a kill)."""
        self.path = path
        rows = []
        if path.exists():
            with open(path, newline="") as f:
                rows = list(csv.DictReader(f))
        text = io.StringIO()
        writer = csv.DictWriter(text, self.FIELDS, extrasaction="ignore")
        writer.writeheader()
        writer.writerows(r for r in rows if int(r["iteration"]) <= keep_through)
        dataset_lib.write_atomic(path, text.getvalue().encode())

    def write(self, row: dict[str, Any]) -> None:
        with open(self.path, "a", newline="") as f:
            csv.writer(f).writerow([_fmt(row.get(k, "")) for k in self.FIELDS])


def _fmt(value: Any) -> Any:
    return f"{value:.6g}" if isinstance(value, float) else value


# -- houses, evaluation, figures -----------------------------------------------------------------


def training_houses(dataset: str, target: str, num_houses: int, num_shards: int,
                    out: pathlib.Path) -> list[pathlib.Path]:
    """Shards of the training houses that have a ``target`` room, one folder of links per worker.

    The houses are the first ``num_houses`` (0: all) of the train split that
    have a room of type ``target``; worker ``i`` gets every ``num_shards``-th
    one from the ``i``-th on (or house ``i mod n`` when there are fewer
    houses than workers).

    Raises:
      ValueError: if no training house has a ``target`` room.
    """
    files = [p for p in dataset_lib.list_houses(dataset, "train") if target in houses.House.load(p).room_types]
    if num_houses:
        files = files[:num_houses]
    if not files:
        raise ValueError(f"no training house of dataset {dataset!r} has a room of type {target!r}")
    folders = []
    for i in range(num_shards):
        folder = out / "houses" / target / f"worker_{i:03d}"
        folder.mkdir(parents=True, exist_ok=True)
        for path in files[i::num_shards] or [files[i % len(files)]]:
            for src in (path, path.with_suffix(".xml")):
                link = folder / src.name
                if not link.exists():
                    tmp = folder / f".{src.name}.tmp"
                    tmp.unlink(missing_ok=True)
                    tmp.symlink_to(src.resolve())
                    os.replace(tmp, link)
        folders.append(folder)
    return folders


def evaluate(subpolicies: dict[str, Any], target: str, config: TrainConfig, split: str,
             seed: int) -> dict[str, dict[str, float]]:
    """Success of sub-policies on the same sampled episodes of a split (sparse reward).

    Starts lie within the distance the curriculum reached at the end of
    training; episodes last ``config.eval_horizon`` steps.

    Args:
      subpolicies: Sub-policies (``reset(target)``, ``act(timestep)``) by name.
      target: Target room type.
      config: The run's configuration.
      split: "train" or "valid".
      seed: Seed of the episode draws.

    Returns:
      For each name: {"success_rate", "episodes", "mean_steps", "max_start_distance"}.
    """
    distance = config.start_distance_at(config.iterations - 1)
    env = leaps_mj.load(config.dataset, split, seed=seed, width=config.width, height=config.height,
                        horizon=config.eval_horizon, reward="sparse", targets=(target,),
                        max_start_distance=distance)
    outcomes = {name: [] for name in subpolicies}
    try:
        for _ in range(config.eval_episodes):
            spec = env.sample_episode()
            for name, policy in subpolicies.items():
                ts = env.reset_to(spec)
                policy.reset(target)
                while not ts.last():
                    ts = env.step(policy.act(ts))
                outcomes[name].append((ts.discount == 0.0, env.task.steps))
    finally:
        env.close()
    return {name: {"success_rate": float(np.mean([s for s, _ in out])), "episodes": len(out),
                   "mean_steps": float(np.mean([n for _, n in out])), "max_start_distance": distance}
            for name, out in outcomes.items()}


def read_progress(path: str | os.PathLike) -> dict[str, np.ndarray]:
    """Columns of a ``progress.csv`` as float arrays (NaN where empty; phase as strings)."""
    with open(path, newline="") as f:
        rows = list(csv.DictReader(f))
    out = {}
    for key in rows[0] if rows else ():
        if key == "phase":
            out[key] = np.array([r[key] for r in rows])
        else:
            out[key] = np.array([float(r[key]) if r[key] != "" else np.nan for r in rows])
    return out


def plot_curves(out: str | os.PathLike, targets: Sequence[str], path: str | os.PathLike) -> None:
    """One panel per target: rollout success of learner- and expert-driven episodes, β and distance."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    from leaps_mj import topdown

    cols = min(3 if len(targets) == 9 else 4, len(targets))
    rows_ = math.ceil(len(targets) / cols)
    fig, axes = plt.subplots(rows_, cols, figsize=(4.2 * cols, 3.2 * rows_), squeeze=False)
    for ax, target in zip(axes.flat, targets):
        log = read_progress(pathlib.Path(out) / target / "progress.csv")
        steps = log["global_step"] / 1000
        ax.plot(steps, log["success_rate"], color="C0", label="success (learner drives)")
        if not np.all(np.isnan(log["mixed_success_rate"])):
            ax.plot(steps, log["mixed_success_rate"], color="C2", alpha=0.6, label="success (expert steps w.p. β)")
        ax.plot(steps, log["beta"], color="C7", ls=":", label="β")
        a2c = np.flatnonzero(log["phase"] == "a2c")
        if len(a2c) and a2c[0] > 0:
            ax.axvline(steps[a2c[0]], color="C3", ls="--", lw=1, label="DAgger → A2C")
        ax.set_ylim(-0.02, 1.02)
        ax.set_title(target)
        ax.set_xlabel("env steps (k)")
        twin = ax.twinx()
        twin.plot(steps, log["start_distance"], color="C1", lw=1, label="max start distance (m)")
        twin.set_ylim(0, max(1.0, np.nanmax(log["start_distance"]) * 1.1))
        twin.tick_params(labelsize=7, colors="C1")
    for ax in axes.flat[len(targets):]:
        ax.axis("off")
    handles, labels = axes.flat[0].get_legend_handles_labels()
    handles.append(matplotlib.lines.Line2D([], [], color="C1", lw=1))
    labels.append("max start distance (m, right axis)")
    fig.legend(handles, labels, loc="lower center", ncol=5, fontsize=8, bbox_to_anchor=(0.5, -0.02))
    fig.suptitle("Sub-policy training: success of rollout episodes (last 50 episodes)")
    fig.tight_layout(rect=(0, 0.04, 1, 1))
    topdown.save_figure(fig, path)


def plot_comparison(runs: dict[str, str | os.PathLike], target: str, path: str | os.PathLike) -> None:
    """Success of learner-driven rollout episodes of one target, for runs of several methods.

    Args:
      runs: Output folders by label (e.g. {"DAgger": "runs/policy_cpu", "A2C": ...}).
      target: The target trained in every run.
      path: PNG to write.
    """
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    from leaps_mj import topdown

    fig, ax = plt.subplots(figsize=(6.5, 3.8))
    for i, (label, folder) in enumerate(runs.items()):
        log = read_progress(pathlib.Path(folder) / target / "progress.csv")
        _, _, extra = nets.load_policy(pathlib.Path(folder) / f"{target}.pt")
        valid = (extra.get("eval") or {}).get("valid/sampled", {}).get("success_rate")
        suffix = f" (valid eval {valid:.2f})" if valid is not None else ""
        ax.plot(log["global_step"] / 1000, log["success_rate"], color=f"C{i}", label=label + suffix)
    ax.set_xlabel("env steps (k)")
    ax.set_ylabel("success of learner-driven episodes")
    ax.set_ylim(-0.02, 1.02)
    ax.set_title(f"{target}: methods on the same budget (last 50 episodes)")
    ax.legend(fontsize=8)
    topdown.save_figure(fig, path)


def run_target(config: TrainConfig, target: str, out: str | os.PathLike, device: str = "cpu",
               progress: bool = True, stop_after: int | None = None) -> dict | None:
    """Trains one target to completion (resuming) and evaluates it once.

    Returns:
      The evaluation results, or None if ``stop_after`` ended the call early.
    """
    from leaps_mj import policies

    trainer = Trainer(config, target, out, device=device, progress=progress)
    trainer.train(stop_after)
    if not trainer.finished:
        return None
    if trainer.eval is None:
        modes = {mode: policies.LearnedSubPolicy(out, targets=(target,), greedy=mode == "greedy", seed=config.seed,
                                                   use_semantic=config.use_semantic)
                 for mode in ("sampled", "greedy")}
        seed = config.seed + 7919 * (1 + rooms.room_index(target))
        trainer.eval = {f"{split}/{mode}": result for split in ("train", "valid")
                        for mode, result in evaluate(modes, target, config, split, seed).items()}
        trainer.save()
    return trainer.eval


# -- command line --------------------------------------------------------------------------------


def _parse_bool(text: str) -> bool:
    if text.lower() in ("1", "true", "yes"):
        return True
    if text.lower() in ("0", "false", "no"):
        return False
    raise argparse.ArgumentTypeError(f"{text!r}: expected true or false")


def _parse_ints(text: str) -> tuple[int, ...]:
    try:
        return tuple(int(v) for v in text.split(","))
    except ValueError:
        raise argparse.ArgumentTypeError(f"{text!r}: expected comma-separated integers") from None


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
    group = parser.add_argument_group("configuration overrides (default: the preset's value)")
    for field in dataclasses.fields(TrainConfig):
        default = field.default
        kind = {bool: _parse_bool, tuple: _parse_ints}.get(type(default), type(default))
        group.add_argument(f"--{field.name.replace('_', '-')}", dest=field.name, type=kind, default=None,
                           metavar=type(default).__name__.upper())
    return parser


def main(argv: Sequence[str] | None = None) -> int:
    args = build_parser().parse_args(argv)
    overrides = {f.name: getattr(args, f.name) for f in dataclasses.fields(TrainConfig)
                 if getattr(args, f.name) is not None}
    config = dataclasses.replace(PRESETS[args.preset], **overrides)
    targets = parse_targets(args.target, config.use_semantic)
    if args.stop_after is not None and args.stop_after < 1:
        raise ValueError(f"--stop-after {args.stop_after}: expected a positive integer")
    if args.threads < 1:
        raise ValueError(f"--threads {args.threads}: expected a positive integer")
    torch.set_num_threads(args.threads)
    out = pathlib.Path(args.out)
    results = {}
    for target in targets:
        results[target] = run_target(config, target, out, args.device, not args.no_progress, args.stop_after)
    print(f"{'target':12} {'train':>8} {'valid':>8} {'valid greedy':>13}  (success on sampled episodes)")
    for target, res in results.items():
        if res is None:
            print(f"{target:12} {'(stopped early; rerun to resume)':>31}")
        else:
            print(f"{target:12} {res['train/sampled']['success_rate']:8.2f} {res['valid/sampled']['success_rate']:8.2f}"
                  f" {res['valid/greedy']['success_rate']:13.2f}")
    if all(r is not None for r in results.values()):
        plot_curves(out, list(targets), out / "training_curves.png")
        print(f"wrote {out / 'training_curves.png'}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
