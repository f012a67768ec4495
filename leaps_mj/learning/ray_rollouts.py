"""Training rollouts on Ray actors: the sub-policy trainer's environments across a cluster.

``python -m leaps_mj.train policy ... --backend ray [--ray-address ADDR] [--num-workers N]``

The run's ``num_envs`` environments are split into contiguous groups, one per
rollout actor (a plain Ray Core actor reserving one CPU). Each actor
(:class:`RolloutWorker`) holds its group of training environments
(:class:`leaps_mj.learning.training_env.TrainingEnv`, with the geodesic expert
for the DAgger labels), a CPU copy of the policy, and its environments'
current time steps and LSTM state, carried from one iteration to the next.
Per iteration the learner puts its weights in the object store once
(``ray.put``); every actor loads them and runs
:func:`leaps_mj.learning.rollouts.collect` on its group (the local backend's
loop, with the β expert-mixing rule and the learner-only environments applied
by global environment index), and the learner merges the fragments, in actor
order, into the one unroll and batch its update takes
(:func:`leaps_mj.learning.rollouts.merge`).

Seeds are explicit: environment ``i`` has the seed and house shard it has on
the local backend (:func:`leaps_mj.learning.rollouts.env_seed`,
:func:`~leaps_mj.learning.rollouts.env_kwargs`), and actor ``a`` draws its
action sampler and expert coins at iteration ``j`` from
``numpy.random.default_rng([seed, network, j, 1 + a])``. The same seed and
number of actors give the same run; another number of actors gives another
(equally valid) run, as the draws are per actor.

**A lost actor** (its process or node died, ``ray.kill``) is replaced by a
fresh one, which runs the iteration again: its environments restart their
episodes (seeded for the iteration it is replaced at, as a resumed session
is) from a zero LSTM state, and the episodes they had not finished are not
counted. Only an actor lost more than ``max_retries`` times in one iteration,
one that fails to start, or an error in the rollout itself stops training.
Checkpoints are the learner's alone, so stopping and resuming work as with
the local backend, and a run may resume on either backend.

Each actor builds its own house shards (links in a temporary folder of its
node), so workers need the dataset at the same path as the driver, not the
driver's output folder. They get the driver's MuJoCo GL settings through the
actor's ``runtime_env`` (:func:`leaps_mj.environment.ray_cluster.worker_env`).
"""

from __future__ import annotations

import contextlib
import pathlib
import tempfile
from typing import Sequence

import numpy as np
import ray
import torch

from leaps_mj.environment import ray_cluster, vector
from leaps_mj.learning import backend_options, nets, rollouts
from leaps_mj.learning.policy_config import TrainConfig
from leaps_mj.learning.training_env import make_training_env

#: Seconds the learner waits for one actor's fragment (its first includes the actor's start-up).
FRAGMENT_TIMEOUT_S = 1800.0


def actor_class(cls):
    """``cls`` as a Ray actor class of this project: one CPU per actor, not restarted, the driver's GL settings."""
    return ray.remote(cls).options(num_cpus=1, max_restarts=0, runtime_env={"env_vars": ray_cluster.worker_env()})


def get_replacing(ref, again, actor: str, result: str, when: str, timeout_s: float, max_retries: int):
    """``ray.get(ref)``; when its actor is lost, ``again()`` (replacing the actor, returning the new ref) is waited on.

    Args:
      ref: The call's object ref.
      again: Replaces the lost actor and makes the same call on it; returns its ref.
      actor, result, when: Words of the errors ("rollout actor 0", "fragment", "iteration 3").
      timeout_s: Seconds to wait for each try.
      max_retries: How many times the actor may be lost.

    Raises:
      RuntimeError: if the actor failed to start or was lost more than ``max_retries`` times.
      TimeoutError: if no result came within ``timeout_s``.
    """
    lost = 0
    while True:
        try:
            return ray.get(ref, timeout=timeout_s)
        except ray.exceptions.GetTimeoutError:
            raise TimeoutError(f"{actor} returned no {result} of {when} in {timeout_s} s "
                               f"(a hung worker, or no free CPU for it)") from None
        except ray.exceptions.RayActorError as e:
            if e.actor_init_failed:
                raise RuntimeError(f"{actor} failed to start: {e}") from e
            lost += 1
            if lost > max_retries:
                raise RuntimeError(f"{actor} was lost {lost} times in {when}") from e
        ref = again()


class _Group:
    """Environments stepped one after another in this process, with the vector env's ``step`` API."""

    def __init__(self, envs: list):
        self.envs = envs

    def step(self, actions: Sequence[int]) -> list:
        return [env.step(action) for env, action in zip(self.envs, actions)]


class RolloutWorker:
    """One rollout actor: a group of the run's environments, a CPU copy of the policy and the carried state.

    A plain class (:class:`RayRollouts` makes it a Ray actor), so that it
    also runs in this process.

    Args:
      config: The run's configuration.
      target: The network's target (:data:`leaps_mj.learning.train_policy.SHARED` for a shared one).
      targets: The run's targets.
      network: The network's index (seeds).
      actor: The actor's index (its draws).
      envs: Global indices of its environments (contiguous).
      first_iteration: Iteration at which it starts (seeds, curriculum).
    """

    def __init__(self, config: TrainConfig, target: str, targets: Sequence[str], network: int, actor: int,
                 envs: Sequence[int], first_iteration: int):
        torch.set_num_threads(1)
        self.config, self.network, self.actor, self.offset = config, network, actor, envs[0]
        self._houses = tempfile.TemporaryDirectory(prefix="leaps_mj_shards_")
        kwargs = rollouts.env_kwargs(config, target, targets, first_iteration, pathlib.Path(self._houses.name))
        seed = rollouts.env_seed(config, network, first_iteration)
        self.envs = _Group([make_training_env(seed + i, config, first_iteration, config.labelled, **kwargs[i])
                            for i in envs])
        self.model = nets.ActorCritic(config.policy_config())
        self.timesteps = [env.reset() for env in self.envs.envs]
        self.state = self.model.initial_state(len(envs))
        self.stats = rollouts.EpisodeStats(len(envs), window=None)

    def collect(self, weights: dict[str, torch.Tensor], iteration: int, beta: float) -> rollouts.Fragment:
        """Runs ``t_max`` steps of the group with the given weights; returns the fragment with its finished episodes."""
        self.model.load_state_dict(weights)
        rng = np.random.default_rng([self.config.seed, self.network, iteration, 1 + self.actor])
        gen = torch.Generator().manual_seed(int(rng.integers(2**63)))
        fragment, self.timesteps, self.state = rollouts.collect(
            self.model, self.envs, self.timesteps, self.state, beta, rng, gen, self.stats, self.config, self.offset)
        fragment.episodes = self.stats.drain()
        return fragment


class ActorGroup:
    """A group of project actors, each serving a contiguous share of ``items`` (environments, episodes).

    The life both Ray training backends share: connect to Ray on entering
    (:func:`leaps_mj.environment.ray_cluster.connected`), start one actor per
    share, put the learner's weights in the object store once per round,
    gather every actor's result in actor order, replacing a lost actor and
    asking it again (:func:`get_replacing`), and end the actors (and Ray, if
    started here) on exit. Subclasses say how an actor starts (:meth:`_start`).

    Args:
      worker_cls: The plain class each actor runs (:func:`actor_class`).
      items: How many items the actors share.
      workers: Actors (None: one per CPU of the cluster, at most ``items``).
      address: The Ray cluster's address (None: a local instance, or the one already initialised).
      max_retries: How many times one actor may be lost in one round before training stops.
      timeout_s: Seconds to wait for one actor's result.
    """

    #: The actors' name in error messages.
    noun = "actor"

    def __init__(self, worker_cls, items: int, workers: int | None, address: str | None, max_retries: int,
                 timeout_s: float):
        self._worker_cls, self._items, self._workers, self._address = worker_cls, items, workers, address
        self._max_retries, self._timeout_s = max_retries, timeout_s
        self._stack = contextlib.ExitStack()
        self._actors: list = []

    @property
    def actors(self) -> list:
        """The live actors' handles, in item order (a copy)."""
        return list(self._actors)

    def __enter__(self):
        self._stack.enter_context(ray_cluster.connected(self._address))
        try:
            workers = self._workers or min(ray_cluster.cluster_cpus(), self._items)
            self._remote = actor_class(self._worker_cls)
            self._groups = vector.split(self._items, workers)
            self._actors = [self._start(a) for a in range(workers)]
        except BaseException:
            self._stack.close()
            raise
        return self

    def _start(self, actor: int):
        """A new actor ``actor`` (its handle)."""
        raise NotImplementedError

    @staticmethod
    def put_weights(module: torch.nn.Module):
        """The module's weights, on the CPU, in the object store (one copy for every actor)."""
        return ray.put({k: v.detach().cpu() for k, v in module.state_dict().items()})

    def gather(self, call, result: str, when: str) -> list:
        """``call(a, actor)`` (an actor method's ref) on every actor, then each result in actor order.

        Raises:
          RuntimeError: if an actor failed to start or was lost more than ``max_retries`` times.
          TimeoutError: if an actor returned nothing within ``timeout_s``.
        """
        refs = [call(a, actor) for a, actor in enumerate(self._actors)]
        return [self._get(a, ref, call, result, when) for a, ref in enumerate(refs)]

    def _get(self, actor: int, ref, call, result: str, when: str):
        def again():
            ray.kill(self._actors[actor])
            self._actors[actor] = self._start(actor)
            return call(actor, self._actors[actor])

        return get_replacing(ref, again, f"{self.noun} {actor}", result, when, self._timeout_s, self._max_retries)

    def close(self) -> None:
        """Ends the actors (their CPUs are free again) and Ray, if it was started here."""
        for actor in self._actors:
            ray.kill(actor)
        self._actors = []
        self._stack.close()

    def __exit__(self, *exc) -> None:
        self.close()


class RayRollouts(ActorGroup):
    """The Ray backend: rollout actors feeding the learner the same unrolls as :class:`rollouts.LocalRollouts`.

    Connects to Ray on entering (:func:`leaps_mj.environment.ray_cluster.connected`)
    and ends its actors on exit. Timings: ``act_forward_seconds`` and
    ``env_wait_seconds`` are summed over the actors (their forward passes and
    environment steps), ``worker_*_seconds`` over the environments.

    Args:
      config: The run's configuration.
      target: The network's target (or the shared network's name).
      targets: The run's targets.
      network: The network's index (seeds).
      first_iteration: Iteration the session starts at.
      workers: Actors (None: one per CPU of the cluster, at most ``num_envs``).
      address: The Ray cluster's address (None: a local instance, or the one already initialised).
      max_retries: How many times one actor may be lost in one iteration before training stops.
      timeout_s: Seconds to wait for one actor's fragment (None: :data:`FRAGMENT_TIMEOUT_S`, read then).
    """

    noun = "rollout actor"

    def __init__(self, config: TrainConfig, target: str, targets: Sequence[str], network: int,
                 first_iteration: int, workers: int | None = None, address: str | None = None,
                 max_retries: int = 3, timeout_s: float | None = None):
        backend_options.check_backend("ray", workers, address, config.num_envs)
        super().__init__(RolloutWorker, config.num_envs, workers, address, max_retries,
                         timeout_s or FRAGMENT_TIMEOUT_S)
        self._args = (config, target, tuple(targets), network)
        # The iteration an actor started now begins at (seeds, curriculum): the session's first, then the current.
        self._iteration = first_iteration

    def _start(self, actor: int):
        return self._remote.remote(*self._args, actor, self._groups[actor], self._iteration)

    def collect(self, model: nets.ActorCritic, iteration: int, beta: float, rng: np.random.Generator,
                stats: rollouts.EpisodeStats) -> tuple[rollouts.Unroll, dict[str, np.ndarray], dict[str, float]]:
        """One iteration's unroll of every environment (see :func:`rollouts.merge`), replacing lost actors.

        ``rng`` (the learner's) is not drawn from: actors draw from their own seeds.

        Raises:
          RuntimeError: if an actor failed to start or was lost more than ``max_retries`` times.
          TimeoutError: if an actor returned no fragment within ``timeout_s``.
        """
        self._iteration = iteration
        weights = self.put_weights(model)
        fragments = self.gather(lambda a, actor: actor.collect.remote(weights, iteration, beta), "fragment",
                                f"iteration {iteration}")
        for fragment in fragments:
            for episode in fragment.episodes:
                stats.add(*episode)
        return rollouts.merge(fragments)
