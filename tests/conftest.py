"""Shared fixtures: a tiny generated house dataset with fixed episodes, a small local Ray instance."""

import pathlib

import pytest

import leaps_mj  # noqa: F401  (selects the GL backend before dm_control loads)
from leaps_mj.environment import episodes
from leaps_mj.world import dataset


@pytest.fixture(scope="session")
def tiny_dataset(tmp_path_factory) -> pathlib.Path:
    """A dataset of 4 / 2 / 3 houses (seed 5) with 5 episodes per plan length."""
    out = tmp_path_factory.mktemp("tiny_dataset")
    dataset.write_dataset(out, {"train": 4, "valid": 2, "test": 3}, seed=5, name="tiny", progress=False)
    for split in ("valid", "test"):
        eps, _ = episodes.generate(str(out), split, per_length=5, seed=0)
        episodes.write(out / "episodes" / f"{split}.jsonl", eps)
    return out


@pytest.fixture(scope="module")
def ray_local():
    """One small local Ray instance (2 CPUs, no dashboard, workers' logs kept off the terminal) per test module."""
    ray = pytest.importorskip("ray")
    ray.init(num_cpus=2, include_dashboard=False, log_to_driver=False)
    yield
    ray.shutdown()
