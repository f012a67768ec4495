"""Ray actors for evaluation jobs: the same jobs as the local pool, across a cluster, nothing lost when one dies.

:class:`ActorPool` is the Ray counterpart of the local ``multiprocessing``
pool (:func:`leaps_mj.evaluation.backends.worker_pool`), with its shape: an
initializer run once per worker, then ``imap_unordered(fn, jobs)``. Each actor
reserves one CPU, builds its state once (the evaluation's environment and
agents) and runs one job at a time.

A job whose actor dies (its process killed, its node lost, ``ray.kill``) is
put back at the head of the queue and the actor replaced by a fresh one; a
job's result is taken only from the run that returned, so none is lost and
none counted twice. An error raised by a job itself, or by the initializer,
is not retried: it is a bug or bad input, and is raised in the driver.

Workers get the driver's MuJoCo GL settings through the actor's
``runtime_env`` (:func:`leaps_mj.environment.ray_cluster.worker_env`), so they
apply before MuJoCo is imported there; the driver opens no GL context. See
docs/ray.md for running on a cluster.
"""

from __future__ import annotations

import collections

import ray

from leaps_mj.environment.ray_cluster import worker_env

#: Seconds to wait for any running job to finish before giving up (a hung worker or a cluster without room).
JOB_TIMEOUT_S = 3600.0


class _Worker:
    """One actor: state built once by ``initializer(*initargs)``, then one job at a time."""

    def __init__(self, initializer, initargs: tuple):
        initializer(*initargs)

    def run(self, fn, job):
        """``fn(job)`` in this actor's process."""
        return fn(job)


class ActorPool:
    """Ray actors running jobs, replacing any that dies and running its job again.

    Args:
      initializer: module-level function building a worker's state (in the actor's process).
      initargs: its arguments.
      workers: actors (see :func:`leaps_mj.environment.ray_cluster.cluster_cpus`).
      max_retries: how many times one job may lose its actor before the pool gives up.
      timeout_s: seconds to wait for some running job to finish (see :data:`JOB_TIMEOUT_S`).

    Raises:
      ValueError: if ``workers`` or ``max_retries`` is out of range.
    """

    def __init__(self, initializer, initargs: tuple, workers: int, max_retries: int = 3,
                 timeout_s: float = JOB_TIMEOUT_S):
        if workers < 1 or max_retries < 0:
            raise ValueError(f"workers {workers!r} and max_retries {max_retries!r}: expected >= 1 and >= 0")
        self._remote = ray.remote(_Worker).options(num_cpus=1, max_restarts=0,
                                                    runtime_env={"env_vars": worker_env()})
        self._init = (initializer, initargs)
        self._max_retries = max_retries
        self._timeout_s = timeout_s
        self._actors = [self._remote.remote(*self._init) for _ in range(workers)]

    @property
    def actors(self) -> list:
        """The live actors' handles (a copy)."""
        return list(self._actors)

    def imap_unordered(self, fn, jobs):
        """Yields ``fn(job)`` for every job, in the order they finish, each exactly once.

        Every actor has a job running whenever one is waiting, also while a result is being yielded.

        Raises:
          RuntimeError: if a job lost its actor more than ``max_retries`` times, or an actor failed to start.
          TimeoutError: if no running job finished within ``timeout_s``.
        """
        queue = collections.deque(enumerate(jobs))
        lost = collections.Counter()
        idle = list(self._actors)
        running = {}  # result ref -> (actor, (job number, job))

        def submit():
            while idle and queue:
                actor, item = idle.pop(), queue.popleft()
                running[actor.run.remote(fn, item[1])] = (actor, item)

        while queue or running:
            submit()
            ready, _ = ray.wait(list(running), num_returns=1, timeout=self._timeout_s)
            if not ready:
                raise TimeoutError(f"no job finished in {self._timeout_s} s; running: "
                                   f"{[item[1] for _, item in running.values()]!r}")
            actor, item = running.pop(ready[0])
            try:
                result = ray.get(ready[0], timeout=self._timeout_s)
            except ray.exceptions.RayActorError as e:
                if e.actor_init_failed:
                    raise RuntimeError(f"a Ray worker failed to start: {e}") from e
                lost[item[0]] += 1
                if lost[item[0]] > self._max_retries:
                    raise RuntimeError(f"job {item[1]!r} lost its worker {lost[item[0]]} times") from e
                queue.appendleft(item)
                idle.append(self._replace(actor))
                continue
            idle.append(actor)
            submit()  # every actor busy while the caller handles the result
            yield result

    def _replace(self, actor):
        """A fresh actor in place of a dead one (its initializer runs again)."""
        ray.kill(actor)
        fresh = self._remote.remote(*self._init)
        self._actors[self._actors.index(actor)] = fresh
        return fresh

    def close(self) -> None:
        """Ends every actor (their CPUs are free again)."""
        for actor in self._actors:
            ray.kill(actor)
        self._actors = []

    def __enter__(self):
        return self

    def __exit__(self, *exc) -> None:
        self.close()
