"""Shared fixtures: a tiny generated house dataset with fixed episodes, a small local Ray instance, the tools/ loader."""

import importlib.util
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


@pytest.fixture(scope="session")
def hop_episodes(tiny_dataset):
    """Starts 1 and 2 doors from each node in the tiny test houses (kept in memory, no file written)."""
    eps, _ = episodes.generate_hops(str(tiny_dataset), "test", per_node=2, seed=0)
    return eps


@pytest.fixture(scope="module")
def ray_local():
    """One small local Ray instance (2 CPUs, no dashboard, workers' logs kept off the terminal) per test module."""
    ray = pytest.importorskip("ray")
    ray.init(num_cpus=2, include_dashboard=False, log_to_driver=False)
    yield
    ray.shutdown()


@pytest.fixture
def ray_two_nodes():
    """A simulated two-node Ray cluster (one CPU per node), connected for one test and shut down after it."""
    ray = pytest.importorskip("ray")
    from ray.cluster_utils import Cluster

    if ray.is_initialized():  # a module's local instance, when it ran first in this process
        ray.shutdown()
    cluster = Cluster(initialize_head=True, head_node_args={"num_cpus": 1, "include_dashboard": False})
    try:
        cluster.add_node(num_cpus=1)
        ray.init(address=cluster.address, log_to_driver=False)
        cluster.wait_for_nodes(timeout=120)
        assert len([n for n in ray.nodes() if n["Alive"]]) == 2
        yield cluster
    finally:
        ray.shutdown()
        cluster.shutdown()


@pytest.fixture
def load_tool():
    """Imports a script of ``tools/`` by name (they are not a package)."""

    def load(name: str):
        path = pathlib.Path(__file__).resolve().parents[1] / "tools" / f"{name}.py"
        spec = importlib.util.spec_from_file_location(name, path)
        tool = importlib.util.module_from_spec(spec)
        spec.loader.exec_module(tool)
        return tool

    return load
