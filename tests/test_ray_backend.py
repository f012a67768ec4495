"""Tests for the Ray evaluation backend: the same CSV bytes as the local one, and no job lost when a worker dies.

The default tests share one local Ray instance (2 CPUs, no dashboard: the
``ray_local`` fixture of conftest.py); the simulated two-node cluster is slow
(``python -m pytest -m slow tests/test_ray_backend.py``).
"""

import functools
import os
import signal
import sys
import time

import pytest

ray = pytest.importorskip("ray")

from ray import cloudpickle

from leaps_mj.environment import ray_cluster
from leaps_mj.evaluation import harness, ray_backend

# This module's helpers run inside actors, which cannot import the test module: send them by value.
cloudpickle.register_pickle_by_value(sys.modules[__name__])

AGENTS = [harness.AGENTS["random"], harness.AGENTS["pure"]]
#: Seconds any single wait on Ray may take in these tests.
TIMEOUT_S = 120


def _local_csvs(config, indices, folder) -> dict[str, bytes]:
    harness.run(config, AGENTS, indices, folder, chunk=1, progress=False)
    return {s.label: harness.csv_path(folder, s.label).read_bytes() for s in AGENTS}


def test_ray_csvs_are_byte_identical_to_the_local_backends(ray_local, tiny_dataset, tmp_path):
    config = harness.EvalConfig(dataset=str(tiny_dataset), split="test", horizon=40)
    local = _local_csvs(config, [0, 1, 2, 3], tmp_path / "local")
    table = harness.run(config, AGENTS, [0, 1, 2, 3], tmp_path / "ray", workers=2, chunk=1, progress=False,
                        backend="ray")
    assert {s.label: harness.csv_path(tmp_path / "ray", s.label).read_bytes() for s in AGENTS} == local
    assert (tmp_path / "ray" / "config.json").read_bytes() == (tmp_path / "local" / "config.json").read_bytes()
    assert [r["episode"] for r in table["pure"]] == [0, 1, 2, 3]


def _nothing():
    """An initializer without state."""


def _slow_identity(job):
    time.sleep(1.0)
    return job


def test_a_job_of_an_actor_killed_with_ray_kill_runs_again_once(ray_local):
    with ray_backend.ActorPool(_nothing, (), workers=2, timeout_s=TIMEOUT_S) as pool:
        results = pool.imap_unordered(_slow_identity, range(5))
        done = [next(results)]
        victim = pool.actors[0]  # every actor has a job running while a result is handed out
        ray.kill(victim)
        done += list(results)
        assert victim not in pool.actors and len(pool.actors) == 2
    assert sorted(done) == [0, 1, 2, 3, 4]


def _die_once_mid_chunk(marker: str, job):
    """Runs the chunk's first episode, then kills this worker's process the first time any worker gets here."""
    spec, indices = job
    harness._run_chunk((spec, indices[:1]))
    try:
        os.close(os.open(marker, os.O_CREAT | os.O_EXCL))
    except FileExistsError:
        return harness._run_chunk(job)
    os.kill(os.getpid(), signal.SIGKILL)


def test_episodes_of_a_killed_worker_process_are_rerun_and_counted_once(ray_local, tiny_dataset, tmp_path):
    config = harness.EvalConfig(dataset=str(tiny_dataset), split="test", horizon=40)
    local = _local_csvs(config, [0, 1, 2, 3, 4], tmp_path / "local")
    out = tmp_path / "ray"
    out.mkdir()
    jobs = [(spec, [0, 1, 2, 3, 4][k:k + 2]) for spec in AGENTS for k in (0, 2, 4)]
    marker = str(tmp_path / "died")
    with ray_backend.ActorPool(harness._init_worker, (config, None, None, 1), workers=2,
                               timeout_s=TIMEOUT_S) as pool:
        for spec, rows in pool.imap_unordered(functools.partial(_die_once_mid_chunk, marker), jobs):
            harness.append_rows(harness.csv_path(out, spec.label), rows)
    assert os.path.exists(marker)  # a worker did die
    assert {s.label: harness.csv_path(out, s.label).read_bytes() for s in AGENTS} == local


def _fail_to_start():
    raise ValueError("no such dataset")


def test_a_worker_that_cannot_start_is_an_error_not_a_retry(ray_local):
    with ray_backend.ActorPool(_fail_to_start, (), workers=1, timeout_s=TIMEOUT_S) as pool, \
            pytest.raises(RuntimeError, match="failed to start"):
        list(pool.imap_unordered(_slow_identity, [0]))


def test_ray_address_while_ray_is_running_is_refused(ray_local):
    with pytest.raises(ValueError, match="already initialised"), ray_cluster.connected("10.0.0.1:6379"):
        pass


@pytest.mark.slow
def test_two_node_cluster_gives_the_local_bytes(tiny_dataset, tmp_path, ray_two_nodes):
    config = harness.EvalConfig(dataset=str(tiny_dataset), split="test", horizon=40)
    local = _local_csvs(config, [0, 1, 2], tmp_path / "local")
    harness.run(config, AGENTS, [0, 1, 2], tmp_path / "ray", workers=None, chunk=1, progress=False,
                backend="ray")  # one actor per cluster CPU: one on each node
    assert {s.label: harness.csv_path(tmp_path / "ray", s.label).read_bytes() for s in AGENTS} == local


def test_workers_get_the_drivers_gl_settings_but_not_a_disabled_backend(monkeypatch):
    monkeypatch.setenv("MUJOCO_GL", "osmesa")
    monkeypatch.setenv("MUJOCO_EGL_DEVICE_ID", "1")
    assert {"MUJOCO_GL": "osmesa", "MUJOCO_EGL_DEVICE_ID": "1"}.items() <= ray_cluster.worker_env().items()
    monkeypatch.setenv("MUJOCO_GL", "disabled")
    assert "MUJOCO_GL" not in ray_cluster.worker_env()
