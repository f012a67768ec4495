"""Shared fixtures: a tiny generated house dataset with fixed episodes."""

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
