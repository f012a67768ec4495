"""The trainers' backend options: where their workers run, and the checks those options need.

``--backend local|ray [--ray-address ADDR] [--num-workers N]`` of the
sub-policy, controller and prior trainers (docs/ray.md). Apart from
:mod:`leaps_mj.learning.rollouts` so that a trainer reads its options without
importing torch and the training environments (the prior trainer needs neither).
"""

from __future__ import annotations

import argparse

#: Where a trainer's workers run (``--backend``): local processes, or Ray actors.
BACKENDS = ("local", "ray")


def check_backend(backend: str, num_workers: int | None, ray_address: str | None, num_items: int,
                  items: str = "num_envs") -> None:
    """Refuses backend options that do not fit together.

    Args:
      backend: One of :data:`BACKENDS`.
      num_workers: Ray actors (None: one per cluster CPU); only with "ray".
      ray_address: Address of a running Ray cluster (None: start a local one); only with "ray".
      num_items: How many items the actors share, each holding at least one (the sub-policy
        run's environments, the controller trainer's episodes per update, the prior trainer's houses).
      items: Their name in the error.

    Raises:
      ValueError: naming the bad value and what was expected.
    """
    if backend not in BACKENDS:
        raise ValueError(f"backend {backend!r}: expected one of {list(BACKENDS)}")
    if backend != "ray":
        for name, value in (("num_workers", num_workers), ("ray_address", ray_address)):
            if value is not None:
                raise ValueError(f"{name} {value!r} needs backend 'ray', not {backend!r}")
    if num_workers is not None and (isinstance(num_workers, bool) or not isinstance(num_workers, int)
                                    or not 1 <= num_workers <= num_items):
        raise ValueError(f"num_workers {num_workers!r}: expected an integer in [1, {items}={num_items}]")


def add_backend_arguments(parser: argparse.ArgumentParser, what: str, workers_help: str) -> None:
    """Adds a trainer's ``--backend``, ``--ray-address`` and ``--num-workers`` (checked by :func:`check_backend`).

    Args:
      parser: The trainer's command.
      what: What runs on the backend ("rollouts", "training episodes").
      workers_help: What one Ray actor holds, and the default number of actors.
    """
    parser.add_argument("--backend", choices=BACKENDS, default="local",
                        help=f"where {what} run: this machine, or Ray actors (docs/ray.md)")
    parser.add_argument("--ray-address", default=None,
                        help="address of a running Ray cluster (with --backend ray; default: start a local one)")
    parser.add_argument("--num-workers", type=int, default=None,
                        help=f"Ray actors, {workers_help} (with --backend ray)")
