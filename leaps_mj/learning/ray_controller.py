"""The controller trainer's training episodes on Ray actors.

``python -m leaps_mj.train controller ... --backend ray [--ray-address ADDR] [--num-workers N]``

Each update's ``batch_episodes`` episodes are split into contiguous groups,
one per actor (a plain Ray Core actor reserving one CPU,
:func:`leaps_mj.learning.ray_rollouts.actor_class`). An actor
(:class:`ControllerWorker`) holds its own environment over the training
houses and a CPU copy of the :class:`~leaps_mj.learning.nets.ControllerNet`;
per update the learner puts its weights in the object store once
(``ray.put``), every actor loads them and plays its episodes with
:func:`leaps_mj.learning.train_controller.run_training_episode`, and the
learner takes the decision records, in episode order, into the same
:func:`~leaps_mj.learning.train_controller.a2c_loss` and update as the local
backend.

Seeds. **The episodes are the local backend's**: there, one environment per
session samples every episode (house, target, start) from its task RNG,
seeded ``SeedSequence([seed, 1, first update])``, and nothing else draws from
it. The learner keeps that RNG's state (``numpy`` ``RandomState``); an actor
sets its environment's task RNG to it, samples all the update's episodes in
order (:meth:`~leaps_mj.environment.roomnav.RoomNavEnvironment.sample_episode`),
plays its own (``reset_to``) and returns the state after the last, which the
learner keeps for the next update. **The decisions are not**: locally the
controller's choices (a torch generator seeded ``[seed, 3, update]``) and
the sub-policy's draws (``[seed, 2, update]``) are streams that an update's
episodes consume one after another, so where episode ``k``'s draws start
depends on how many draws episodes ``0..k-1`` made, known only once they are
played. On Ray, episode ``k`` of update ``u`` has its own seeds
``[seed, 3, u, k]`` and ``[seed, 2, u, k]`` and a fresh sub-policy, so a run
is the same for any number of actors, and an episode replayed on a
replacement actor is the same episode. Ray records also carry their episode
spec (``record["episode"]``).

**A lost actor** (its process or node died, ``ray.kill``) is replaced by a
fresh one, which plays the lost actor's episodes of the update again, from the
same weights, RNG state and seeds. Only an actor lost more than
``max_retries`` times in one update, one that fails to start, or an error in
an episode stops training. Checkpoints are the learner's alone, so a run may
resume on either backend.

This module does not import :mod:`leaps_mj.learning.train_controller` (which
imports it when the backend is chosen; no import cycles): the trainer hands
it its configuration (``TrainConfig``), episode function and sub-policy factory.
"""

from __future__ import annotations

from typing import Callable, Sequence

import numpy as np
import torch

from leaps_mj.environment import roomnav
from leaps_mj.learning import baselines, nets, ray_rollouts

#: Seconds the learner waits for one actor's episodes (its first call includes the actor's start-up).
EPISODES_TIMEOUT_S = 1800.0


def episode_seed(config, stream: int, update: int, episode: int) -> int:
    """Seed of stream ``stream`` (2: sub-policy, 3: controller sampling) of episode ``episode`` of update ``update``."""
    return int(np.random.SeedSequence([config.seed, stream, update, episode]).generate_state(1)[0])


def sampler_state(config, first_update: int) -> tuple:
    """The state of the episode-sampling RNG of a session starting at ``first_update`` (the local backend's)."""
    seed = int(np.random.SeedSequence([config.seed, 1, first_update]).generate_state(1)[0])
    return np.random.RandomState(seed).get_state()


class _Replay:
    """The environment with ``reset`` starting the given episode (for the trainer's episode function)."""

    def __init__(self, env: roomnav.RoomNavEnvironment, spec: roomnav.EpisodeSpec):
        self._env, self._spec = env, spec

    def reset(self):
        return self._env.reset_to(self._spec)

    def __getattr__(self, name):
        return getattr(self._env, name)


class ControllerWorker:
    """One actor: an environment over the training houses and a CPU copy of the controller.

    A plain class (:class:`RayController` makes it a Ray actor), so that it also runs in this process.

    Args:
      config: The run's ``train_controller.TrainConfig``.
      run_episode: ``train_controller.run_training_episode`` (env, agent, config) -> record.
      make_subpolicy: ``train_controller.make_subpolicy`` (config, env, seed) -> sub-policy.
    """

    def __init__(self, config, run_episode: Callable, make_subpolicy: Callable):
        torch.set_num_threads(1)
        self.config, self._run_episode, self._make_subpolicy = config, run_episode, make_subpolicy
        self.env = roomnav.load(config.dataset, "train", seed=0, width=config.width, height=config.height,
                                horizon=config.horizon, reward="sparse")
        self.net = nets.ControllerNet(nets.ControllerConfig(lstm=config.lstm)).eval()

    def play(self, weights: dict[str, torch.Tensor], update: int, state: tuple,
             episodes: Sequence[int]) -> tuple[list[dict], tuple]:
        """Plays episodes ``episodes`` of update ``update`` from the sampler state ``state``.

        Returns their records (with ``"episode"``, the spec) and the sampler's state after the update's episodes.
        """
        c = self.config
        self.net.load_state_dict(weights)
        self.env.task.random.set_state(state)
        specs = [self.env.sample_episode() for _ in range(c.batch_episodes)]
        after = self.env.task.random.get_state()
        records = []
        for k in episodes:
            sub = self._make_subpolicy(c, self.env, episode_seed(c, 2, update, k))
            agent = baselines.ControllerAgent(sub, self.net, c.option_steps, seed=episode_seed(c, 3, update, k))
            record = self._run_episode(_Replay(self.env, specs[k]), agent, c)
            records.append({**record, "episode": specs[k]})
        return records, after

    def close(self) -> None:
        self.env.close()


class RayController(ray_rollouts.ActorGroup):
    """The Ray backend of the controller trainer: actors playing each update's episodes.

    Connects to Ray on entering (:func:`leaps_mj.environment.ray_cluster.connected`) and ends its actors on exit.

    Args:
      config: The run's ``train_controller.TrainConfig``.
      run_episode, make_subpolicy: See :class:`ControllerWorker`.
      first_update: The update the session starts at (the sampler's seed).
      workers: Actors (None: one per cluster CPU, at most ``batch_episodes``; checked by the trainer).
      address: The Ray cluster's address (None: a local instance, or the one already initialised).
      max_retries: How many times one actor may be lost in one update before training stops.
      timeout_s: Seconds to wait for one actor's episodes (None: :data:`EPISODES_TIMEOUT_S`, read then).
    """

    noun = "controller actor"

    def __init__(self, config, run_episode: Callable, make_subpolicy: Callable, first_update: int,
                 workers: int | None = None, address: str | None = None, max_retries: int = 3,
                 timeout_s: float | None = None):
        super().__init__(ControllerWorker, config.batch_episodes, workers, address, max_retries,
                         timeout_s or EPISODES_TIMEOUT_S)
        self._worker_args = (config, run_episode, make_subpolicy)
        self.config = config
        self._state = sampler_state(config, first_update)

    def _start(self, actor: int):
        return self._remote.remote(*self._worker_args)

    def play(self, net: nets.ControllerNet, update: int) -> list[dict]:
        """The records of update ``update``'s episodes, in order, played with ``net``'s weights; replaces lost actors.

        Raises:
          RuntimeError: if an actor failed to start or was lost more than ``max_retries`` times.
          TimeoutError: if an actor returned no episodes within ``timeout_s``.
        """
        weights = self.put_weights(net)
        state = self._state
        results = self.gather(lambda a, actor: actor.play.remote(weights, update, state, self._groups[a]),
                              "episodes", f"update {update}")
        self._state = results[0][1]
        # Writable copies: arrays from the object store are read-only.
        return [{k: np.array(v) if isinstance(v, np.ndarray) else v for k, v in record.items()}
                for records, _ in results for record in records]
