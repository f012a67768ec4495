"""Where evaluation jobs run: this process, a local process pool, or Ray actors on a cluster.

Both worker backends have one shape, that of ``multiprocessing.Pool``: an
initializer builds a worker's state once (environment, agents), then
``imap_unordered(fn, jobs)`` yields results as they finish. The harness
(:func:`leaps_mj.evaluation.harness.run`) builds one job list and appends
every result to the same resumable CSVs whichever backend ran it.

* ``local``: ``--workers`` spawned processes on this machine (the default).
* ``ray``: ``--workers`` actors (default: one per CPU of the cluster) on the
  Ray cluster at ``--ray-address``, or on a local Ray instance sized to this
  machine without one; a job whose actor dies is run again
  (:mod:`leaps_mj.evaluation.ray_backend`, docs/ray.md). Ray is imported only
  for this backend.
"""

from __future__ import annotations

import argparse
import contextlib
import dataclasses
import multiprocessing

from leaps_mj.learning.backend_options import BACKENDS


@dataclasses.dataclass(frozen=True)
class Backend:
    """Where worker jobs run.

    Attributes:
      name: "local" or "ray".
      workers: worker processes (local) or actors (ray); None: 1 locally, one
        per CPU of the cluster on Ray.
      address: the Ray cluster's address (``ray start --head`` prints it);
        None starts a local Ray instance. Only with ``name="ray"``.
    """

    name: str = "local"
    workers: int | None = None
    address: str | None = None

    def __post_init__(self):
        if self.name not in BACKENDS:
            raise ValueError(f"backend {self.name!r}: expected one of {list(BACKENDS)}")
        if self.workers is not None and (isinstance(self.workers, bool) or not isinstance(self.workers, int)
                                         or self.workers < 1):
            raise ValueError(f"workers {self.workers!r}: expected a positive integer")
        if self.address is not None and self.name != "ray":
            raise ValueError(f"ray address {self.address!r} needs backend 'ray', not {self.name!r}")

    def in_process(self, n_jobs: int) -> bool:
        """Whether ``n_jobs`` jobs run in this process: none at all (no worker is started, no Ray
        connected), one local worker, or a single job locally."""
        return n_jobs == 0 or self.name == "local" and ((self.workers or 1) == 1 or n_jobs == 1)


@contextlib.contextmanager
def worker_pool(backend: Backend, initializer, initargs: tuple, n_jobs: int):
    """A pool of worker processes, each running ``initializer(*initargs)`` once; closed on exit.

    Args:
      backend: a backend whose jobs do not run in this process.
      initializer: module-level function (workers import it by name).
      initargs: its arguments (pickled to every worker).
      n_jobs: how many jobs there are (no more workers are started).

    Yields:
      an object with ``imap_unordered(fn, jobs)``.
    """
    if backend.name == "ray":
        from leaps_mj.environment import ray_cluster
        from leaps_mj.evaluation import ray_backend

        with ray_cluster.connected(backend.address), ray_backend.ActorPool(
                initializer, initargs, min(backend.workers or ray_cluster.cluster_cpus(), n_jobs)) as pool:
            yield pool
        return
    pool = multiprocessing.get_context("spawn").Pool(min(backend.workers or 1, n_jobs), initializer, initargs)
    try:
        yield pool
    finally:
        pool.terminate()
        pool.join()


def add_arguments(parser: argparse.ArgumentParser) -> None:
    """Adds ``--backend``, ``--workers`` (alias ``--num-workers``) and ``--ray-address`` to a command."""
    parser.add_argument("--backend", choices=BACKENDS, default="local",
                        help="local: a process pool on this machine; ray: actors on a Ray cluster (docs/ray.md)")
    parser.add_argument("--workers", "--num-workers", dest="workers", type=int, default=None,
                        help="worker processes (local, default 1) or Ray actors (default: one per cluster CPU)")
    parser.add_argument("--ray-address", default=None,
                        help="address of a running Ray cluster (with --backend ray; default: start a local one)")


def from_arguments(parser: argparse.ArgumentParser, args: argparse.Namespace) -> Backend:
    """The :class:`Backend` the options of :func:`add_arguments` ask for; exits with a usage error on bad values."""
    if args.workers is not None and args.workers < 1:
        parser.error(f"--workers/--num-workers {args.workers}: expected a positive integer")
    if args.ray_address is not None and args.backend != "ray":
        parser.error(f"--ray-address {args.ray_address!r} needs --backend ray (not {args.backend!r})")
    return Backend(args.backend, args.workers, args.ray_address)
