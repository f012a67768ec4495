"""Tests for the controller trainer's Ray backend: the local backend's episodes, a killed actor replaced, resume.

Decisions are not compared with the local backend's: there, an update's
episodes draw their choices from one stream each (see
:mod:`leaps_mj.learning.ray_controller`), so only the episodes (house,
target, start) can match; the Ray backend's decisions are checked to be
independent of how episodes are split among actors.
"""

import dataclasses

import numpy as np
import pytest

ray = pytest.importorskip("ray")

from leaps_mj.learning import nets, ray_controller, train_controller

#: Seconds any single wait on Ray may take in these tests.
TIMEOUT_S = 120


def tiny(dataset, **overrides):
    return dataclasses.replace(train_controller.PRESETS["tiny"], dataset=str(dataset), **overrides)


def _key(spec) -> tuple:
    return spec.house, spec.target, tuple(np.round(spec.start, 9))


@pytest.fixture(scope="module")
def local_episodes(tiny_dataset, tmp_path_factory):
    """The episodes (house, target, start) of a tiny local run, per update."""
    played = []
    run_episode = train_controller.run_training_episode

    def recording(env, agent, config):
        record = run_episode(env, agent, config)
        played.append(_key(env.episode))
        return record

    with pytest.MonkeyPatch.context() as patch:
        patch.setattr(train_controller, "run_training_episode", recording)
        config = tiny(tiny_dataset)
        train_controller.Trainer(config, tmp_path_factory.mktemp("local"), progress=False).train()
    b = config.batch_episodes
    return [played[i:i + b] for i in range(0, len(played), b)]


def test_a_worker_plays_the_local_backends_episodes_whatever_the_split(tiny_dataset, local_episodes):
    config = tiny(tiny_dataset)
    weights = nets.ControllerNet(nets.ControllerConfig(lstm=config.lstm)).state_dict()
    one, two = (ray_controller.ControllerWorker(config, train_controller.run_training_episode,
                                               train_controller.make_subpolicy) for _ in range(2))
    try:
        state = ray_controller.sampler_state(config, 0)
        for update, want in enumerate(local_episodes):
            records, after = one.play(weights, update, state, [0, 1])
            assert [_key(r["episode"]) for r in records] == want
            # Episode 1 alone on another actor: the same episode and decisions (per-episode seeds).
            (alone,), after_alone = two.play(weights, update, state, [1])
            for name in ("inputs", "choices", "rewards"):
                np.testing.assert_array_equal(alone[name], records[1][name], err_msg=name)
            assert alone["steps"] == records[1]["steps"] and alone["success"] == records[1]["success"]
            assert all(np.array_equal(x, y) for x, y in zip(after[1:], after_alone[1:]))
            state = after
    finally:
        one.close()
        two.close()


@pytest.mark.parametrize("bad, match", [
    (["--backend", "ray", "--num-workers", "0"], r"num_workers 0: expected an integer in \[1, batch_episodes=2\]"),
    (["--backend", "ray", "--num-workers", "3"], r"num_workers 3: expected an integer in \[1, batch_episodes=2\]"),
    (["--num-workers", "2"], r"num_workers 2 needs backend 'ray', not 'local'"),
    (["--ray-address", "10.0.0.1:6379"], r"ray_address '10.0.0.1:6379' needs backend 'ray', not 'local'"),
])
def test_bad_backend_options_are_refused_naming_the_value(tiny_dataset, tmp_path, bad, match):
    with pytest.raises(ValueError, match=match):
        train_controller.main(["--preset", "tiny", "--dataset", str(tiny_dataset), "--subpolicy", "local",
                               "--out", str(tmp_path / "run"), "--no-progress", *bad])
    assert not (tmp_path / "run").exists()


@pytest.fixture(scope="module")
def ray_run(ray_local, tiny_dataset, tmp_path_factory):
    """A tiny run on 2 actors, actor 0 killed after update 1. Returns (config, out, actors per update, killed, episodes)."""
    out = tmp_path_factory.mktemp("ray_run")
    config = tiny(tiny_dataset)
    run = train_controller.Trainer(config, out, progress=False, backend="ray", num_workers=2)
    actors, killed, played = [], [], []
    play = run.play

    def play_then_kill():
        records = play()
        played.append([_key(r["episode"]) for r in records])
        if run.update == 0:
            killed.append(run._ray.actors[0])
            ray.kill(killed[0])
        actors.append(run._ray.actors)
        return records

    run.play = play_then_kill
    with pytest.MonkeyPatch.context() as patch:
        patch.setattr(ray_controller, "EPISODES_TIMEOUT_S", TIMEOUT_S)
        run.train()
    assert run.finished
    return config, out, actors, killed[0], played


def test_ray_actors_play_the_local_backends_episodes(ray_run, local_episodes):
    *_, played = ray_run
    assert played == local_episodes


def test_a_killed_actor_is_replaced_and_training_goes_on(ray_run):
    _, out, actors, killed, _ = ray_run
    assert len(actors) == 2 and all(len(a) == 2 for a in actors)
    assert killed == actors[0][0] and killed not in actors[1] and actors[1][1] == actors[0][1]
    run = train_controller.Trainer(ray_run[0], out, progress=False)  # resumes on the local backend: finished
    assert run.finished and [h["update"] for h in run.history] == [1, 2]
    for row in run.history:
        assert all(np.isfinite(row[k]) for k in ("policy_loss", "value_loss", "entropy"))
