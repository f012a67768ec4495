"""Tests for the prior trainer's Ray backend: the local backend's counts, a killed actor replaced, resume."""

import dataclasses
import json

import numpy as np
import pytest

ray = pytest.importorskip("ray")

from leaps_mj.learning import ray_prior, train_prior

#: Seconds any single wait on Ray may take in these tests.
TIMEOUT_S = 120


def tiny(dataset, **overrides):
    return dataclasses.replace(train_prior.PRESETS["tiny"], dataset=str(dataset), **overrides)


@pytest.fixture(scope="module")
def local_counts(tiny_dataset, tmp_path_factory):
    return train_prior.learn(tiny(tiny_dataset), tmp_path_factory.mktemp("local"), progress=False)


def test_ray_actors_count_as_the_local_backend_with_a_killed_actor_replaced(
        ray_local, tiny_dataset, tmp_path, local_counts, monkeypatch):
    monkeypatch.setattr(ray_prior, "HOUSE_TIMEOUT_S", TIMEOUT_S)
    run = train_prior.Trainer(tiny(tiny_dataset), tmp_path, progress=False, backend="ray", num_workers=2)
    iterate, actors = run.iterate, []

    def iterate_then_kill():
        row = iterate()
        actors.append(run._ray.actors)
        if run.iteration == 0:  # the first house is counted: its actor dies before the next round
            ray.kill(actors[0][0])
        return row

    run.iterate = iterate_then_kill
    run.train()
    assert run.finished and len(actors) == 3
    assert actors[2][0] != actors[0][0] and actors[2][1] == actors[0][1], "actor 0 replaced, actor 1 kept"
    got = run.result()
    np.testing.assert_array_equal(got["pos"], local_counts["pos"])
    np.testing.assert_array_equal(got["trials"], local_counts["trials"])
    state = json.loads((tmp_path / "state.json").read_text())
    assert state["house"] == 3 and np.array_equal(state["pos"], local_counts["pos"])


def test_a_ray_run_resumes_a_local_one_to_the_same_counts(ray_local, tiny_dataset, tmp_path, local_counts,
                                                          monkeypatch):
    monkeypatch.setattr(ray_prior, "HOUSE_TIMEOUT_S", TIMEOUT_S)
    config = tiny(tiny_dataset)
    train_prior.Trainer(config, tmp_path, progress=False).train(stop_after=1)
    rest = train_prior.learn(config, tmp_path, progress=False, backend="ray", num_workers=1)
    assert rest["resumed"] == 1
    np.testing.assert_array_equal(rest["pos"], local_counts["pos"])
    np.testing.assert_array_equal(rest["trials"], local_counts["trials"])


@pytest.mark.parametrize("bad, match", [
    (["--backend", "ray", "--num-workers", "4"], r"num_workers 4: expected an integer in \[1, houses=3\]"),
    (["--num-workers", "2"], r"num_workers 2 needs backend 'ray', not 'local'"),
    (["--ray-address", "10.0.0.1:6379"], r"ray_address '10.0.0.1:6379' needs backend 'ray', not 'local'"),
])
def test_bad_backend_options_are_refused_naming_the_value(tiny_dataset, tmp_path, bad, match):
    with pytest.raises(ValueError, match=match):
        train_prior.main(["--preset", "tiny", "--dataset", str(tiny_dataset), "--out", str(tmp_path / "run"), *bad])
    assert not (tmp_path / "run" / "state.json").exists()
