"""The sub-policy trainer's environments: training houses per target, expert labels, worker processes.

Each worker process runs a :class:`TrainingEnv`: a RoomNav environment over
its shard of the training houses that have a room of the target type, with
the teacher's action (the DAgger label: the geodesic or the observable
expert, ``TrainConfig.teacher``) and per-step timings added to the observation.
"""

from __future__ import annotations

import dataclasses
import functools
import os
import pathlib
import time
from typing import Sequence

import numpy as np

from leaps_mj.environment import mapping, roomnav, vector
from leaps_mj.learning import nets
from leaps_mj.learning.policy_config import TEACHERS, TrainConfig
from leaps_mj.world import dataset as dataset_lib
from leaps_mj.world import houses, rooms

#: Share of a vertical strip's pixels that must show a node's room for its room-view label.
VIEW_MIN_FRACTION = 0.02


def room_view(nodes: np.ndarray) -> np.ndarray:
    """The room-view label of a frame of per-pixel graph nodes.

    Args:
      nodes: (H, W) ints, the graph node of each pixel's room
        (``len(GRAPH_NODES)`` where it belongs to none: walls, doors, sky).

    Returns:
      (K + 1, VIEW_COLUMNS) uint8: 1 where at least :data:`VIEW_MIN_FRACTION`
      of the strip's pixels show a room of that node.
    """
    height, width = nodes.shape
    n = len(rooms.GRAPH_NODES)
    columns = np.arange(width) * nets.VIEW_COLUMNS // width
    flat = (nodes.astype(np.intp) * nets.VIEW_COLUMNS + columns).ravel()
    counts = np.bincount(flat, minlength=(n + 1) * nets.VIEW_COLUMNS).reshape(n + 1, nets.VIEW_COLUMNS)[:n]
    strip = height * np.bincount(columns, minlength=nets.VIEW_COLUMNS)
    return (counts >= VIEW_MIN_FRACTION * strip).astype(np.uint8)


class TrainingEnv:
    """Worker-side wrapper of a RoomNav environment for training.

    Runs in the environment's worker process and adds to every observation:

    * ``expert_action`` (int64 scalar): the teacher's action for the state
      (-1 when labelling is off), the DAgger label;
    * ``step_seconds`` (float64 (3,)): seconds this step spent in physics and
      collisions (``Task.before_step``), in rendering and the success test
      (``Task.after_step``) and in the teacher — for the throughput benchmark;
    * with ``config.shared``, ``node`` (uint8 (K + 1,)): the one-hot of the
      episode's graph node, the shared network's target input;
    * with ``config.prev_action``, ``prev_action`` (int64): the action that
      led to this step (-1 at an episode's first step);
    * with ``config.map_input``, ``egomap`` (uint8 (C, S, S)): the
      egocentric map of the episode so far
      (:class:`leaps_mj.environment.mapping.EgoMapper`), built here, in the
      worker process, from the observation alone;
    * with ``config.aux_coef > 0``, the auxiliary labels: ``room_view``
      (uint8 (K + 1, VIEW_COLUMNS)), 1 where at least
      :data:`VIEW_MIN_FRACTION` of a vertical strip of the frame shows a room
      of that node (its floor, ceiling or furniture), and ``target_distance``
      (float32), the geodesic metres to the target.

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
      seed: Seed of the teacher's random moves.
      label: Whether to compute expert labels.
    """

    def __init__(self, env, config: TrainConfig, first_iteration: int, seed: int, label: bool):
        self._env = env
        self._config = config
        self._steps = first_iteration * config.t_max
        self._expert = TEACHERS[config.teacher](env, seed=seed) if label else None
        self._last = True
        self._times = np.zeros(3)
        self._mappers: dict[str, mapping.EgoMapper] = {}
        self._mapper: mapping.EgoMapper | None = None
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

    def _augment(self, ts, action: int = -1):
        self._last = ts.last()
        t0 = time.perf_counter()
        label = self._expert.act() if self._expert is not None and not ts.last() else -1
        self._times[2] += time.perf_counter() - t0
        obs = dict(ts.observation, expert_action=np.int64(label), step_seconds=self._times.copy())
        self._times[:] = 0.0
        task = self._env.task
        if self._config.shared:
            obs["node"] = np.eye(len(rooms.GRAPH_NODES), dtype=np.uint8)[task.target_index]
        if self._config.prev_action:
            obs["prev_action"] = np.int64(action)
        if self._config.map_input:
            obs["egomap"] = self._map(ts)
        if self._config.aux_coef > 0:
            obs["room_view"] = room_view(self._env.segment_luts[2].take(task.segments))
            obs["target_distance"] = np.float32(task.distance)
        return ts._replace(observation=obs)

    def _map(self, ts) -> np.ndarray:
        """The episode's egocentric map after this step (a new map at an episode's first step)."""
        if ts.first():
            target = rooms.GRAPH_NODES[self._env.task.target_index]
            if target not in self._mappers:
                self._mappers[target] = mapping.EgoMapper(target, self._config.width, self._config.height)
            self._mapper = self._mappers[target]
            self._mapper.reset()
        obs = ts.observation
        return self._mapper.update(obs["segmentation"], obs["depth"], obs["pose"])

    def reset(self):
        distance = self._config.start_distance_at(self._steps // self._config.t_max)
        if self._env.config.max_start_distance != distance:
            self._env.config = dataclasses.replace(self._env.config, max_start_distance=distance)
        return self._augment(self._env.reset())

    def step(self, action):
        self._steps += 1
        if self._last:
            return self.reset()
        return self._augment(self._env.step(action), int(action))

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
    """A worker's :class:`TrainingEnv` (the ``make_env`` of :class:`leaps_mj.environment.vector.VectorEnv`)."""
    return TrainingEnv(roomnav.load(seed=seed, **env_kwargs), config, first_iteration, seed, label)


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


def training_houses(dataset: str, target: str | None, num_houses: int, num_shards: int,
                    out: pathlib.Path, name: str | None = None) -> list[pathlib.Path]:
    """Shards of the training houses that have a ``target`` room, one folder of links per worker.

    The houses are the first ``num_houses`` (0: all) of the train split that
    have a room of type ``target`` (any house when ``target`` is None);
    worker ``i`` gets every ``num_shards``-th one from the ``i``-th on (or
    house ``i mod n`` when there are fewer houses than workers). The folders
    lie under ``out/houses/<name>`` (default: the target).

    Raises:
      ValueError: if no training house has a ``target`` room.
    """
    files = [p for p in dataset_lib.list_houses(dataset, "train")
             if target is None or target in houses.House.load(p).room_types]
    if num_houses:
        files = files[:num_houses]
    if not files:
        raise ValueError(f"no training house of dataset {dataset!r} has a room of type {target!r}")
    folders = []
    for i in range(num_shards):
        folder = out / "houses" / (name or target) / f"worker_{i:03d}"
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
