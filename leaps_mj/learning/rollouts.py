"""Rollouts of the sub-policy trainer: the step loop both backends share, and the local backend.

A rollout backend hands the learner, once per iteration, one :class:`Unroll`
of all the run's environments and the A2C batch, so that the update
(:meth:`leaps_mj.learning.train_policy.Trainer._update`) does not care where
the samples came from. Every backend runs the same loop, :func:`collect`,
over a group of environments: ``t_max`` steps with the policy acting, the β
expert-mixing rule and the learner-only environments applied by *global*
environment index. It returns a :class:`Fragment`: the group's columns of the
unroll (with the LSTM state at the fragment's start) and the rewards,
discounts and value estimates of the n-step returns. :func:`merge`
concatenates fragments along the environment axis and computes the returns.

* :class:`LocalRollouts` (the default): the run's environments in local
  worker processes (:func:`leaps_mj.learning.training_env.training_vector_env`),
  stepped in lock-step with the learner's network: one fragment per iteration.
* :class:`leaps_mj.learning.ray_rollouts.RayRollouts`: rollout actors on Ray,
  each running :func:`collect` on its own environments with a CPU copy of the
  policy: one fragment per actor.

Whichever backend runs it, environment ``i`` of a session started at
iteration ``j`` has seed ``env_seed(config, network, j) + i`` and the
``i``-th shard of the training houses (:func:`env_kwargs`).
"""

from __future__ import annotations

import collections
import dataclasses
import pathlib
import time
from typing import Sequence

import numpy as np
import torch

from leaps_mj.environment import vector
from leaps_mj.learning import nets
from leaps_mj.learning.losses import n_step_returns
from leaps_mj.learning.policy_config import TrainConfig
from leaps_mj.learning.training_env import training_houses, training_vector_env

@dataclasses.dataclass
class Unroll:
    """``t_max`` steps of ``num_envs`` environments, as stored for updates.

    Segmentation is uint8, depth float16 (the aggregated dataset keeps many).
    """

    obs: dict[str, np.ndarray]  # the network's inputs (T, B, ...): segmentation, depth [, semantic, target] [, node]
    first: np.ndarray  # (T, B) float32, 1 where an episode began
    valid: np.ndarray  # (T, B) float32, 0 at LAST observations (their action is ignored)
    labels: np.ndarray  # (T, B) int64 expert actions (-1: none)
    state: tuple[np.ndarray, np.ndarray]  # LSTM (h, c) at the unroll's start
    aux: dict[str, np.ndarray] = dataclasses.field(default_factory=dict)  # auxiliary labels (T, B, ...)

    def tensors(self, device) -> tuple[dict, torch.Tensor, tuple[torch.Tensor, torch.Tensor]]:
        obs = nets.ActorCritic.preprocess(self.obs, device)
        first = torch.as_tensor(self.first, device=device)
        state = tuple(torch.as_tensor(s, device=device) for s in self.state)
        return obs, first, state

    def aux_tensors(self, device) -> dict[str, torch.Tensor]:
        return {k: torch.as_tensor(v, device=device) for k, v in self.aux.items()}


class EpisodeStats:
    """Outcomes of the last ``window`` episodes finished in rollouts: learner-driven or mixed.

    :meth:`record` follows each environment's steps (summing its return);
    :meth:`add` takes an outcome recorded elsewhere (a rollout actor's
    :meth:`drain`).

    Args:
      num_envs: Environments followed by :meth:`record`.
      window: Outcomes kept per kind (None: all, until drained).
    """

    def __init__(self, num_envs: int, window: int | None = 50):
        self.returns = np.zeros(num_envs)
        self.recent = {"learner": collections.deque(maxlen=window), "mixed": collections.deque(maxlen=window)}
        self.finished = 0

    def record(self, i: int, ts, mixed: bool) -> None:
        if ts.reward is not None:
            self.returns[i] += ts.reward
        if ts.last():
            self.add("mixed" if mixed else "learner", float(ts.discount == 0.0), self.returns[i])
            self.returns[i] = 0.0

    def add(self, who: str, success: float, episode_return: float) -> None:
        """Counts a finished episode: ``who`` drove it ("learner" or "mixed"), whether it succeeded, its return."""
        self.recent[who].append((success, episode_return))
        self.finished += 1

    def drain(self) -> list[tuple[str, float, float]]:
        """The outcomes kept so far as :meth:`add` arguments, forgetting them."""
        out = [(who, *item) for who, items in self.recent.items() for item in items]
        for items in self.recent.values():
            items.clear()
        return out

    def summary(self) -> dict[str, float]:
        out = {}
        for who, items in self.recent.items():
            if items:
                arr = np.array(items)
                prefix = "" if who == "learner" else "mixed_"
                out[f"{prefix}success_rate"] = float(arr[:, 0].mean())
                out[f"{prefix}episode_return"] = float(arr[:, 1].mean())
        return out


@dataclasses.dataclass
class Fragment:
    """``t_max`` steps of a group of K environments: their columns of the unroll and of the A2C batch.

    All arrays are (T, K); ``unroll.state`` is the group's LSTM state at the
    fragment's start, each (K, lstm).
    """

    unroll: Unroll
    actions: np.ndarray  # int64, the actions taken (the expert's or the learner's)
    rewards: np.ndarray  # float64, reward of the step from s_t (0 at LAST observations)
    discounts: np.ndarray  # float64, γ times the environment's discount of that step
    next_values: np.ndarray  # float64, value estimate of s_{t+1}
    bootstrap: np.ndarray  # bool, where R_{t+1} is not available (see losses.n_step_returns)
    times: dict[str, float]  # seconds spent acting, stepping, in physics, rendering and the expert
    #: Episodes finished during the fragment, as :meth:`EpisodeStats.add` arguments (remote groups only).
    episodes: list[tuple[str, float, float]] = dataclasses.field(default_factory=list)


def env_seed(config: TrainConfig, network: int, iteration: int) -> int:
    """Seed of environment 0 of a session started at ``iteration`` (environment ``i`` gets this plus ``i``).

    Args:
      network: The network's index (a target's room index, or the shared network's).
    """
    return (config.seed * 1000 + network) * 100_000 + iteration * config.num_envs


def env_kwargs(config: TrainConfig, target: str, targets: Sequence[str], iteration: int,
               out: pathlib.Path) -> list[dict]:
    """The :func:`leaps_mj.load` arguments of each of the run's environments at ``iteration``.

    Environment ``i`` gets the ``i``-th shard of the training houses (links
    under ``out/houses/<target>``), the curriculum's start distance and the
    run's targets.
    """
    c = config
    shards = training_houses(c.dataset, None if c.shared else target, c.num_houses, c.num_envs, out, name=target)
    return [dict(houses_dir=str(shard), width=c.width, height=c.height, horizon=c.horizon, reward="shaped",
                 targets=tuple(targets), max_start_distance=c.start_distance_at(iteration),
                 max_start_doors=c.max_start_doors or None)
            for shard in shards]


def elapsed(device: torch.device, since: float) -> float:
    """Seconds since ``since``, after the device's queued work is done."""
    if device.type == "cuda":
        torch.cuda.synchronize(device)
    return time.perf_counter() - since


def collect(model: nets.ActorCritic, envs, timesteps: list, state: nets.State, beta: float,
            rng: np.random.Generator, gen: torch.Generator, stats: EpisodeStats, config: TrainConfig,
            offset: int = 0) -> tuple[Fragment, list, nets.State]:
    """Runs ``t_max`` steps of a group of environments with the policy; returns a fragment and the carried state.

    Environment ``k`` of the group is the run's environment ``offset + k``:
    the run's first ``config.learner_envs`` are driven by the learner alone;
    in the others each step is the expert's with probability ``beta`` (where
    it has a label), else the learner's sample.

    Args:
      model: The policy (its device is the one the forward passes run on).
      envs: The group's environments: ``step(actions) -> [TimeStep]``.
      timesteps: Their current time steps.
      state: The LSTM state before ``timesteps``.
      beta: Probability that the expert takes a step of a mixed environment.
      rng: Draws the expert-mixing coins (K per step).
      gen: Draws the learner's actions.
      stats: Follows the group's episodes (index ``k``).
      config: The run's configuration.
      offset: Global index of the group's first environment.

    Returns:
      (the fragment, the time steps after it, the LSTM state after it).
    """
    c = config
    device = next(model.parameters()).device
    T, B = c.t_max, len(timesteps)
    keys = model.input_keys()
    aux_keys = ("room_view", "semantic", "target_distance") if c.aux_coef > 0 else ()
    stored = {"segmentation": np.uint8, "depth": np.float16, "target_distance": np.float32, "prev_action": np.int8}
    first, valid = np.zeros((T, B), np.float32), np.zeros((T, B), np.float32)
    labels, actions = np.zeros((T, B), np.int64), np.zeros((T, B), np.int64)
    rewards, discounts = np.zeros((T, B)), np.zeros((T, B))
    values, bootstrap = np.zeros((T + 1, B)), np.zeros((T, B), bool)
    start_state = tuple(s.detach().cpu().numpy() for s in state)
    learner_only = offset + np.arange(B) < c.learner_envs
    columns: dict[str, np.ndarray] = {}
    times = collections.Counter()
    for t in range(T + 1):
        obs = {k: vector.stack(timesteps, k) for k in set(keys + aux_keys + ("expert_action",))}
        is_first = np.array([ts.first() for ts in timesteps], np.float32)
        f0 = time.perf_counter()
        with torch.no_grad():
            x = nets.ActorCritic.preprocess({k: obs[k] for k in keys}, device)
            logits, value, new_state = model(x, state, torch.as_tensor(is_first, device=device))
            learner = torch.multinomial(torch.softmax(logits, -1), 1, generator=gen).squeeze(-1).cpu().numpy()
        times["act_forward_seconds"] += elapsed(device, f0)
        values[t] = value.cpu().numpy()
        if t == T:
            break
        state = new_state
        for k in set(keys + aux_keys):
            if k not in columns:
                columns[k] = np.zeros((T, *obs[k].shape), stored.get(k, np.uint8))
            columns[k][t] = obs[k]
        first[t], labels[t] = is_first, obs["expert_action"]
        valid[t] = [not ts.last() for ts in timesteps]
        expert = (rng.random(B) < beta) & ~learner_only & (labels[t] >= 0)
        actions[t] = np.where(expert, labels[t], learner)
        e0 = time.perf_counter()
        timesteps = envs.step([int(a) for a in actions[t]])
        times["env_wait_seconds"] += time.perf_counter() - e0
        for i, ts in enumerate(timesteps):
            stats.record(i, ts, not learner_only[i] and beta > 0)
            times["worker_physics_seconds"] += ts.observation["step_seconds"][0]
            times["worker_render_seconds"] += ts.observation["step_seconds"][1]
            times["worker_expert_seconds"] += ts.observation["step_seconds"][2]
            if valid[t, i]:
                rewards[t, i] = ts.reward
                discounts[t, i] = c.gamma * ts.discount
            bootstrap[t, i] = ts.last() or t == T - 1
    unroll = Unroll({k: columns[k] for k in keys}, first, valid, labels, start_state,
                    {k: columns[k] for k in aux_keys})
    return Fragment(unroll, actions, rewards, discounts, values[1:], bootstrap, dict(times)), timesteps, state


def merge(fragments: Sequence[Fragment]) -> tuple[Unroll, dict[str, np.ndarray], dict[str, float]]:
    """The fragments of all the run's environments, in order, as one unroll, its A2C batch and the summed timings.

    Returns:
      (the unroll, ``{"actions": (T, B) int64, "returns": (T, B) float32 n-step returns}``, seconds by timer).
    """
    def cat(get):
        return np.concatenate([get(f) for f in fragments], axis=1)

    head = fragments[0].unroll
    unroll = Unroll({k: cat(lambda f: f.unroll.obs[k]) for k in head.obs}, cat(lambda f: f.unroll.first),
                    cat(lambda f: f.unroll.valid), cat(lambda f: f.unroll.labels),
                    tuple(np.concatenate([f.unroll.state[j] for f in fragments]) for j in range(len(head.state))),
                    {k: cat(lambda f: f.unroll.aux[k]) for k in head.aux})
    returns = n_step_returns(cat(lambda f: f.rewards), cat(lambda f: f.discounts), cat(lambda f: f.next_values),
                             cat(lambda f: f.bootstrap))
    times = collections.Counter()
    for f in fragments:
        times.update(f.times)
    return unroll, {"actions": cat(lambda f: f.actions), "returns": returns.astype(np.float32)}, dict(times)


class LocalRollouts:
    """The default backend: the run's environments in local worker processes, stepped with the learner's network.

    The learner's own ``rng`` draws the action sampler's seed and the
    expert-mixing coins (:meth:`collect`). Timings: ``act_forward_seconds``
    and ``env_wait_seconds`` are the learner's, ``worker_*_seconds`` summed
    over the environments.

    Args:
      config: The run's configuration.
      kwargs: One dict of :func:`leaps_mj.load` arguments per environment (:func:`env_kwargs`).
      seed: Environment ``i`` gets ``seed + i`` (:func:`env_seed`).
      first_iteration: Iteration the session starts at (the curriculum's clock).
    """

    def __init__(self, config: TrainConfig, kwargs: Sequence[dict], seed: int, first_iteration: int):
        self.config = config
        self._envs = training_vector_env(kwargs, seed, config, first_iteration, config.labelled)
        self._timesteps = self._envs.reset()
        self._state = None

    def collect(self, model: nets.ActorCritic, iteration: int, beta: float, rng: np.random.Generator,
                stats: EpisodeStats) -> tuple[Unroll, dict[str, np.ndarray], dict[str, float]]:
        """One iteration's unroll of every environment (see :func:`merge`); the LSTM state starts at zero."""
        device = next(model.parameters()).device
        gen = torch.Generator(device=device).manual_seed(int(rng.integers(2**63)))
        if self._state is None:
            self._state = model.initial_state(self.config.num_envs, device)
        fragment, self._timesteps, self._state = collect(model, self._envs, self._timesteps, self._state, beta,
                                                         rng, gen, stats, self.config)
        return merge([fragment])

    def close(self) -> None:
        self._envs.close()

    def __enter__(self):
        return self

    def __exit__(self, *exc) -> None:
        self.close()
