"""Ray for the project's workers: connecting to a cluster, and the environment variables every actor needs.

Both Ray backends use these helpers: evaluation actors
(:mod:`leaps_mj.evaluation.ray_backend`) and the sub-policy trainer's rollout
actors (:mod:`leaps_mj.learning.ray_rollouts`). They live in the
environment stage, below both (stages import only downward), because what
they settle is how an environment worker starts: the MuJoCo GL settings must
reach a worker before it imports MuJoCo. Ray is imported only by the modules
of the Ray backends; see docs/ray.md for running on a cluster.
"""

from __future__ import annotations

import contextlib
import os

import ray

from leaps_mj.environment import gl_backend

#: Environment variables passed from the driver to every actor when set: MuJoCo reads the GL ones at import.
FORWARDED_ENV = ("MUJOCO_GL", "MUJOCO_EGL_DEVICE_ID", "PYOPENGL_PLATFORM", "LP_NUM_THREADS")


def worker_env() -> dict[str, str]:
    """The ``runtime_env`` variables of every actor: the driver's :data:`FORWARDED_ENV`.

    A ``MUJOCO_GL`` of :data:`leaps_mj.environment.gl_backend.DISABLED` (the driver found no GL backend) is not
    passed on: it says nothing of the worker nodes, which then pick their
    own (:mod:`leaps_mj.environment.gl_backend`).
    """
    env = {k: os.environ[k] for k in FORWARDED_ENV if k in os.environ}
    if env.get("MUJOCO_GL") == gl_backend.DISABLED:
        del env["MUJOCO_GL"]
    return env


@contextlib.contextmanager
def connected(address: str | None = None):
    """Ray connected for the block: to the cluster at ``address``, or a new local instance sized to this machine.

    An instance already initialised in this process (a test's, the caller's)
    is used as it is and left running; one started here is shut down on exit.

    Raises:
      ValueError: if ``address`` is given while Ray is already initialised, or cannot be reached.
    """
    if ray.is_initialized():
        if address is not None:
            raise ValueError(f"ray address {address!r}: Ray is already initialised in this process")
        yield
        return
    try:
        if address is None:
            ray.init(include_dashboard=False)
        else:
            ray.init(address=address)
    except ConnectionError as e:
        raise ValueError(f"ray address {address!r}: {e}") from e
    try:
        yield
    finally:
        ray.shutdown()


def cluster_cpus() -> int:
    """CPUs of the connected cluster (at least 1): the default number of actors, one per CPU."""
    return max(1, int(ray.cluster_resources().get("CPU", 1)))
