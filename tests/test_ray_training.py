"""Tests for the sub-policy trainer's rollouts on Ray: the local backend's unrolls, a killed actor replaced, resume.

The default tests run the rollout workers in this process and one tiny run on
the shared local Ray instance (2 CPUs: the ``ray_local`` fixture of
conftest.py). The slow ones (``python -m pytest -m slow tests/test_ray_training.py``)
check that two runs with the same seed and actors are the same run, and run
on a simulated two-node cluster.
"""

import dataclasses
import shutil

import numpy as np
import pytest
import torch

ray = pytest.importorskip("ray")


from leaps_mj.learning import checkpoints, nets, policy_eval, ray_rollouts, rollouts, train_policy, trainer
from leaps_mj.world import rooms

#: Seconds any single wait on Ray may take in these tests.
TIMEOUT_S = 120


def tiny(dataset, **overrides):
    return dataclasses.replace(train_policy.PRESETS["tiny"], dataset=str(dataset), **overrides)


def _argv(dataset, out, *extra):
    return ["--preset", "tiny", "--dataset", str(dataset), "--target", "kitchen", "--out", str(out),
            "--no-progress", *extra]


def test_worker_fragments_merge_into_the_local_backends_unroll(tiny_dataset, tmp_path):
    """Two rollout workers (run in this process) over environments [0] and [1] against the local backend.

    Environment 0 is the learner's alone (its actions are sampled, so only
    its shapes can match); environment 1 is mixed with β = 1, so every step
    is the expert's and both backends must give the same trajectory, over two
    iterations (time steps and LSTM state carried). The worker holding
    environment 1 applies the mixing rule by its global index.
    """
    config = tiny(tiny_dataset, shared=True, aux_coef=0.5, max_start_doors=2, learner_envs=1)
    network = len(rooms.GRAPH_NODES)
    torch.manual_seed(0)
    model = nets.ActorCritic(config.policy_config())
    kwargs = rollouts.env_kwargs(config, train_policy.SHARED, rooms.GRAPH_NODES, 0, tmp_path)
    workers = [ray_rollouts.RolloutWorker(config, train_policy.SHARED, rooms.GRAPH_NODES, network, a, [a], 0)
               for a in (0, 1)]
    with rollouts.LocalRollouts(config, kwargs, rollouts.env_seed(config, network, 0), 0) as local:
        for iteration in (0, 1):
            want = local.collect(model, iteration, 1.0, np.random.default_rng(iteration),
                                 rollouts.EpisodeStats(config.num_envs))
            fragments = [w.collect(model.state_dict(), iteration, 1.0) for w in workers]
            got = rollouts.merge(fragments)
            (u, batch, times), (v, want_batch, want_times) = got, want
            fields = {"first": (u.first, v.first), "valid": (u.valid, v.valid), "labels": (u.labels, v.labels),
                      "h": (u.state[0], v.state[0]), "c": (u.state[1], v.state[1]),
                      **{f"obs/{k}": (u.obs[k], v.obs[k]) for k in v.obs},
                      **{f"aux/{k}": (u.aux[k], v.aux[k]) for k in v.aux},
                      **{f"batch/{k}": (batch[k], want_batch[k]) for k in want_batch}}
            assert set(u.obs) == set(v.obs) == {"segmentation", "depth", "node"}
            assert set(u.aux) == set(v.aux) and set(times) == set(want_times)
            valid = v.valid[:, 1] > 0
            for name, (a, b) in fields.items():
                assert (a.shape, a.dtype) == (b.shape, b.dtype), name
                if name in ("h", "c"):  # (B, lstm): the same weights at another batch size
                    np.testing.assert_allclose(a[1], b[1], rtol=1e-5, atol=1e-6, err_msg=name)
                elif name == "batch/returns":
                    np.testing.assert_allclose(a[:, 1], b[:, 1], rtol=1e-5, atol=1e-6, err_msg=name)
                elif name == "batch/actions":  # a LAST observation's action is the learner's sample, and ignored
                    np.testing.assert_array_equal(a[valid, 1], b[valid, 1], err_msg=name)
                else:
                    np.testing.assert_array_equal(a[:, 1], b[:, 1], err_msg=name)
            assert (batch["actions"][valid, 1] == u.labels[valid, 1]).all(), "environment 1 follows the expert"


def test_a_worker_is_deterministic_in_its_seeds(tiny_dataset):
    config = tiny(tiny_dataset, method="dagger", beta_min=0.5)
    weights = nets.ActorCritic(config.policy_config()).state_dict()
    a, b = (ray_rollouts.RolloutWorker(config, "kitchen", ("kitchen",), 0, 1, [0, 1], 3) for _ in range(2))
    fa, fb = a.collect(weights, 3, 0.5), b.collect(weights, 3, 0.5)
    for x, y in ((fa.actions, fb.actions), (fa.unroll.labels, fb.unroll.labels), (fa.rewards, fb.rewards),
                 (fa.unroll.obs["depth"], fb.unroll.obs["depth"])):
        np.testing.assert_array_equal(x, y)


@pytest.mark.parametrize("bad, match", [
    (["--backend", "ray", "--num-workers", "0"], r"num_workers 0: expected an integer in \[1, num_envs=2\]"),
    (["--backend", "ray", "--num-workers", "3"], r"num_workers 3: expected an integer in \[1, num_envs=2\]"),
    (["--num-workers", "2"], r"num_workers 2 needs backend 'ray', not 'local'"),
    (["--ray-address", "10.0.0.1:6379"], r"ray_address '10.0.0.1:6379' needs backend 'ray', not 'local'"),
])
def test_bad_rollout_options_are_refused_naming_the_value(tiny_dataset, tmp_path, bad, match):
    with pytest.raises(ValueError, match=match):
        train_policy.main(_argv(tiny_dataset, tmp_path, *bad))
    assert not (tmp_path / "kitchen").exists()


@pytest.fixture(scope="module")
def ray_run(ray_local, tiny_dataset, tmp_path_factory):
    """A tiny run on 2 actors stopped after 4 iterations, actor 0 killed after iteration 2; then resumed to the end.

    Returns (config, out folder, the actors after each iteration, the killed actor, the stopped run's policy file).
    """
    out = tmp_path_factory.mktemp("ray_run")
    config = tiny(tiny_dataset)
    run = train_policy.Trainer(config, "kitchen", out, progress=False, backend="ray", num_workers=2)
    actors, killed = [], []
    iterate = run.iterate

    def iterate_then_kill():
        row = iterate()
        if run.iteration == 1:  # the second iteration is done
            killed.append(run._rollouts.actors[0])
            ray.kill(killed[0])
        actors.append(run._rollouts.actors)
        return row

    run.iterate = iterate_then_kill
    with pytest.MonkeyPatch.context() as patch:
        patch.setattr(ray_rollouts, "FRAGMENT_TIMEOUT_S", TIMEOUT_S)
        run.train(stop_after=4)
        stopped = out / "stopped.pt"
        shutil.copy(out / "kitchen.pt", stopped)
        assert train_policy.main(_argv(tiny_dataset, out, "--backend", "ray", "--num-workers", "2")) == 0
    return config, out, actors, killed[0], stopped


def test_a_killed_actor_is_replaced_and_training_goes_on(ray_run):
    _, out, actors, killed, _ = ray_run
    assert len(actors) == 4 and all(len(a) == 2 for a in actors)
    assert killed == actors[1][0] and killed not in actors[2] and actors[2][1] == actors[1][1]
    log = policy_eval.read_progress(out / "kitchen" / "progress.csv")
    assert np.isfinite(log["bc_cross_entropy"][:4]).all() and np.isfinite(log["policy_loss"][4:]).all()


def test_a_stopped_ray_run_resumes_and_its_checkpoint_fits_either_backend(ray_run):
    config, out, _, _, stopped = ray_run
    _, _, extra = checkpoints.load_policy(stopped, config.width, config.height)
    assert extra["iteration"] == 4 and extra["train_config"] == trainer.plain(dataclasses.asdict(config))
    log = policy_eval.read_progress(out / "kitchen" / "progress.csv")
    assert list(log["iteration"]) == [1, 2, 3, 4, 5, 6] and list(log["phase"]) == ["dagger"] * 4 + ["a2c"] * 2
    local = train_policy.Trainer(config, "kitchen", out, progress=False)  # the same configuration
    assert local.finished and local.global_step == 6 * config.batch


def test_a_ray_run_ends_with_a_loadable_evaluated_policy(ray_run):
    config, out, _, _, _ = ray_run
    _, pconfig, extra = checkpoints.load_policy(out / "kitchen.pt", config.width, config.height)
    assert pconfig == config.policy_config() and extra["iteration"] == 6
    assert set(extra["eval"]) == {"train/sampled", "train/greedy", "valid/sampled", "valid/greedy"}


def _fingerprint(out) -> tuple:
    """A finished run's logged scalars (timings aside) and final weights."""
    log = policy_eval.read_progress(out / "kitchen" / "progress.csv")
    scalars = {k: list(map(str, v)) for k, v in log.items() if not k.endswith("_seconds") and k != "SPS"}
    model, _, _ = checkpoints.load_policy(out / "kitchen.pt")
    return scalars, {k: v.numpy().tobytes() for k, v in model.state_dict().items()}


@pytest.mark.slow
def test_the_same_seed_and_actors_give_the_same_run(ray_local, tiny_dataset, tmp_path, monkeypatch):
    monkeypatch.setattr(ray_rollouts, "FRAGMENT_TIMEOUT_S", TIMEOUT_S)
    config = tiny(tiny_dataset, total_steps=4 * 16)
    for name in ("a", "b"):
        train_policy.Trainer(config, "kitchen", tmp_path / name, progress=False, backend="ray",
                             num_workers=2).train()
    assert _fingerprint(tmp_path / "a") == _fingerprint(tmp_path / "b")


@pytest.mark.slow
def test_two_node_cluster_trains_with_an_actor_per_node(tiny_dataset, tmp_path, monkeypatch, ray_two_nodes):
    monkeypatch.setattr(ray_rollouts, "FRAGMENT_TIMEOUT_S", TIMEOUT_S)
    # One actor per cluster CPU by default; each reserves the one CPU of its node.
    run = train_policy.Trainer(tiny(tiny_dataset, total_steps=3 * 16), "kitchen", tmp_path, progress=False,
                               backend="ray")
    workers, iterate = [], run.iterate
    run.iterate = lambda: (workers.append(len(run._rollouts.actors)), iterate())[1]
    run.train()
    assert run.finished and workers == [2, 2, 2]
    log = policy_eval.read_progress(tmp_path / "kitchen" / "progress.csv")
    assert list(log["iteration"]) == [1, 2, 3] and np.isfinite(log["value_loss"]).all()
