"""Tests of leaps_mj.learning.train_policy: returns, losses, tiny training runs, resume."""

import dataclasses

import numpy as np
import pytest
import torch

from leaps_mj.learning import checkpoints, losses, nets, policy_eval, train_policy


def tiny(dataset, **overrides):
    return dataclasses.replace(train_policy.PRESETS["tiny"], dataset=str(dataset), **overrides)


def test_n_step_returns_hand_example():
    # Two envs, three steps, gamma 0.5. Env 0: its episode ends at step 1
    # with a success (discount 0), so step 1 does not bootstrap and step 0
    # uses step 1's return; step 2 (a LAST observation) is invalid and its
    # value is irrelevant but must still be finite. Env 1 is truncated at
    # the horizon after step 0 (discount 1: bootstrap from V(s_1) = 4).
    rewards = np.array([[1.0, 2.0], [10.0, 3.0], [0.0, 1.0]])
    discounts = np.array([[0.5, 0.5], [0.0, 0.5], [0.0, 0.5]])
    next_values = np.array([[99.0, 4.0], [99.0, 6.0], [99.0, 8.0]])
    bootstrap = np.array([[False, True], [True, False], [True, True]])
    got = losses.n_step_returns(rewards, discounts, next_values, bootstrap)
    r1_env1 = 1.0 + 0.5 * 8.0  # step 2 bootstraps from V(s_3) = 8
    want = np.array([
        [1.0 + 0.5 * 10.0, 2.0 + 0.5 * 4.0],
        [10.0, 3.0 + 0.5 * r1_env1],
        [0.0, r1_env1],
    ])
    np.testing.assert_allclose(got, want)


def test_n_step_returns_requires_final_bootstrap():
    z = np.zeros((2, 1))
    with pytest.raises(ValueError, match="bootstrap"):
        losses.n_step_returns(z, z, z, np.zeros((2, 1), bool))


def test_a2c_loss_masks_invalid_steps_and_normalises():
    torch.manual_seed(0)
    config = train_policy.PRESETS["tiny"]
    logits = torch.randn(4, 3, 9, requires_grad=True)
    values = torch.randn(4, 3, requires_grad=True)
    actions = torch.randint(0, 9, (4, 3))
    returns = torch.randn(4, 3)
    valid = torch.ones(4, 3)
    valid[2, 1] = 0.0
    loss, scalars = losses.a2c_loss(logits, values, actions, returns, valid, config)
    loss.backward()
    assert torch.isfinite(loss)
    assert logits.grad[2, 1].abs().sum() == 0 and values.grad[2, 1] == 0
    assert 0 < scalars["entropy"] <= np.log(9) + 1e-6
    # Changing an invalid step's return changes nothing.
    returns2 = returns.clone()
    returns2[2, 1] = 1e6
    loss2, _ = losses.a2c_loss(logits, values, actions, returns2, valid, config)
    assert torch.allclose(loss, loss2)


def test_bc_loss_is_cross_entropy_and_accuracy():
    logits = torch.tensor([[[5.0] + [0.0] * 8, [0.0] * 8 + [5.0]]])  # (T=1, B=2, 9)
    labels = torch.tensor([[0, 3]])
    ce, acc = losses.bc_loss(logits, labels, torch.ones(1, 2))
    want = (torch.nn.functional.cross_entropy(logits[0], labels[0], reduction="none")).mean()
    assert torch.isclose(ce, want) and acc == 0.5


def test_curriculum_and_beta_schedules():
    c = train_policy.TrainConfig(method="dagger+a2c", total_steps=1000 * 64 * 30, dagger_fraction=0.5,
                                 beta_fraction=0.5, start_distance=4.0, distance_step=3.0,
                                 curriculum_iterations=100, max_distance=12.0)
    assert [c.start_distance_at(i) for i in (0, 99, 100, 250, 10_000)] == [4.0, 4.0, 7.0, 10.0, 12.0]
    assert c.dagger_iterations == 500
    assert c.beta_at(0) == 1.0 and c.beta_at(125) == 0.5 and c.beta_at(250) == 0.0 and c.beta_at(600) == 0.0
    floored = dataclasses.replace(c, beta_min=0.3)
    assert floored.beta_at(200) == 0.3 and floored.beta_at(499) == 0.3 and floored.beta_at(500) == 0.0


@pytest.mark.parametrize("bad", [dict(method="ppo"), dict(num_envs=0), dict(gamma=1.5), dict(lr=0.0),
                                 dict(conv_channels=()), dict(learner_envs=3), dict(beta_min=-0.1)])
def test_config_rejects_bad_values(bad):
    with pytest.raises(ValueError):
        dataclasses.replace(train_policy.PRESETS["tiny"], **bad)


def test_cli_overrides_every_field():
    parser = train_policy.build_parser()
    args = parser.parse_args(["--preset", "tiny", "--lr", "0.01", "--conv-channels", "4,4", "--method", "a2c",
                              "--normalize-advantages", "false"])
    assert (args.lr, args.conv_channels, args.method, args.normalize_advantages) == (0.01, (4, 4), "a2c", False)
    dests = {a.dest for a in parser._actions}
    assert {f.name for f in dataclasses.fields(train_policy.TrainConfig)} <= dests


@pytest.fixture(scope="module")
def resumed_run(tiny_dataset, tmp_path_factory):
    """A tiny run killed after iteration 3 (last checkpoint at 2), then resumed to the end.

    Returns (config, out folder, the trainer as saved at the kill, the trainer loaded from it).
    """
    out = tmp_path_factory.mktemp("run")
    config = tiny(tiny_dataset, total_steps=6 * 16, checkpoint_every=2, dagger_fraction=0.5)
    argv = ["--preset", "tiny", "--dataset", str(tiny_dataset), "--target", "kitchen", "--out", str(out),
            "--total-steps", "96", "--checkpoint-every", "2", "--dagger-fraction", "0.5", "--no-progress"]
    assert train_policy.main(argv + ["--stop-after", "3"]) == 0
    killed = train_policy.Trainer(config, "kitchen", out, progress=False)
    assert killed.iteration == 3
    # A kill after iteration 3 was logged but before its checkpoint: the state says 2.
    checkpoints.save_checkpoint(killed.state_path, killed.model, killed.model.config,
                         {**killed.extra(), "iteration": 2, "global_step": 2 * config.batch,
                          "optimizer": killed.optimizer.state_dict()})
    loaded = train_policy.Trainer(config, "kitchen", out, progress=False)
    assert train_policy.main(argv) == 0
    return config, out, killed, loaded


def test_resume_continues_the_same_config_and_counters(resumed_run):
    config, out, killed, loaded = resumed_run
    assert (loaded.iteration, loaded.global_step) == (2, 2 * config.batch)
    for a, b in zip(killed.model.state_dict().values(), loaded.model.state_dict().values()):
        assert torch.equal(a, b)
    assert loaded.optimizer.state_dict()["state"], "optimizer state restored"
    final = train_policy.Trainer(config, "kitchen", out, progress=False)
    assert final.finished and final.iteration == config.iterations == 6
    log = policy_eval.read_progress(out / "kitchen" / "progress.csv")
    assert list(log["iteration"]) == [1, 2, 3, 4, 5, 6]  # the uncheckpointed row 3 was redone once
    with pytest.raises(ValueError, match="lr: saved"):
        train_policy.Trainer(dataclasses.replace(config, lr=0.5), "kitchen", out, progress=False)


def test_training_losses_are_finite_in_both_phases(resumed_run):
    _, out, _, _ = resumed_run
    log = policy_eval.read_progress(out / "kitchen" / "progress.csv")
    assert list(log["phase"]) == ["dagger"] * 3 + ["a2c"] * 3
    assert np.isfinite(log["bc_cross_entropy"][:3]).all() and np.isfinite(log["policy_loss"][3:]).all()
    assert np.isfinite(log["value_loss"]).all() and np.isfinite(log["entropy"][3:]).all()
    assert (log["SPS"] > 0).all()


def test_the_run_leaves_a_loadable_evaluated_policy_and_curves(resumed_run):
    config, out, _, _ = resumed_run
    _, pconfig, extra = checkpoints.load_policy(out / "kitchen.pt", config.width, config.height)
    assert pconfig == config.policy_config() and extra["iteration"] == 6 and extra["target"] == "kitchen"
    assert set(extra["eval"]) == {"train/sampled", "train/greedy", "valid/sampled", "valid/greedy"}
    assert all(0.0 <= r["success_rate"] <= 1.0 and r["episodes"] == config.eval_episodes
               for r in extra["eval"].values())
    assert (out / "training_curves.png").stat().st_size > 0


def test_init_from_starts_a_new_run_from_another_runs_weights(resumed_run, tmp_path):
    """A new run (e.g. A2C fine-tuning) starts from the given policy's weights; a resume keeps its own."""
    config, out, _, _ = resumed_run
    shipped, _, _ = checkpoints.load_policy(out / "kitchen.pt")
    fine = dataclasses.replace(config, method="a2c", init_from=str(out / "kitchen.pt"), lr=1e-4)
    trainer = train_policy.Trainer(fine, "kitchen", tmp_path, progress=False)
    assert all(torch.equal(a, b) for a, b in zip(shipped.state_dict().values(), trainer.model.state_dict().values()))
    from_folder = train_policy.Trainer(dataclasses.replace(fine, init_from=str(out)), "kitchen", tmp_path / "dir",
                                       progress=False)
    assert all(torch.equal(a, b) for a, b in zip(shipped.state_dict().values(),
                                                 from_folder.model.state_dict().values())), "<folder>/kitchen.pt"
    trainer.train(1)
    resumed = train_policy.Trainer(fine, "kitchen", tmp_path, progress=False)
    assert resumed.iteration == 1
    moved = [not torch.equal(a, b) for a, b in zip(shipped.state_dict().values(), resumed.model.state_dict().values())]
    assert any(moved), "resumed, not re-initialised"
    with pytest.raises(ValueError, match="expected this run's"):
        train_policy.Trainer(dataclasses.replace(fine, lstm=8), "kitchen", tmp_path / "other", progress=False)
    with pytest.raises(ValueError, match="does not exist"):
        train_policy.Trainer(dataclasses.replace(fine, init_from=str(tmp_path / "none.pt")), "kitchen",
                             tmp_path / "third", progress=False)


def test_mu_s_training_stores_and_feeds_the_bits(tiny_dataset, tmp_path):
    """A tiny μ_s run: unrolls carry bits and target, both phases train, the result loads as μ_s."""
    from leaps_mj.learning import policies
    from leaps_mj.world import rooms

    config = tiny(tiny_dataset, total_steps=4 * 16, dagger_fraction=0.5, use_semantic=True)
    trainer = train_policy.Trainer(config, "kitchen", tmp_path, progress=False)
    unrolls = []
    update = trainer._update
    trainer._update = lambda unroll, batch, rng: (unrolls.append(unroll), update(unroll, batch, rng))[1]
    trainer.train()
    assert trainer.finished and len(unrolls) == config.iterations
    T, B, K = config.t_max, config.num_envs, rooms.NUM_ROOM_TYPES
    for unroll in unrolls:
        assert unroll.obs["semantic"].shape == unroll.obs["target"].shape == (T, B, K)
        np.testing.assert_array_equal(unroll.obs["target"][..., rooms.room_index("kitchen")], 1)
        assert unroll.obs["target"].sum() == T * B
        assert not unroll.aux, "no auxiliary labels without aux_coef"
    assert any(u.obs["semantic"].any() for u in unrolls), "agents in typed rooms see bits"
    log = policy_eval.read_progress(tmp_path / "kitchen" / "progress.csv")
    assert np.isfinite(log["bc_cross_entropy"][:2]).all() and np.isfinite(log["policy_loss"][2:]).all()
    policy = policies.LearnedSubPolicy(tmp_path, targets=("kitchen",), use_semantic=True)
    assert policy.nets["kitchen"].config.use_semantic


def test_parse_targets():
    from leaps_mj.world import rooms

    assert train_policy.parse_targets("all", False) == rooms.GRAPH_NODES
    assert train_policy.parse_targets("all", True) == rooms.ROOM_TYPES
    assert train_policy.parse_targets("kitchen, indoor", False) == ("kitchen", "indoor")
    with pytest.raises(ValueError, match="'attic'"):
        train_policy.parse_targets("kitchen,attic", False)
    with pytest.raises(ValueError, match="twice"):
        train_policy.parse_targets("kitchen,kitchen", False)


def test_the_train_command_reports_bad_values_in_one_line(capsys):
    from leaps_mj import train

    assert train.main(["policy", "--target", "attic", "--out", "/nonexistent"]) == 2
    err = capsys.readouterr().err
    assert err.startswith("error: target 'attic'") and "Traceback" not in err


def test_shared_run_with_aux_trains_one_network_that_serves_every_node(tiny_dataset, tmp_path):
    """A tiny shared run with auxiliary losses: unrolls carry the node one-hot and consistent labels,
    the losses are finite, and shared.pt serves each graph node through LearnedSubPolicy."""
    from leaps_mj.learning import policies, policy_folder
    from leaps_mj.world import rooms

    config = tiny(tiny_dataset, total_steps=4 * 16, method="dagger", shared=True, aux_coef=0.5, max_start_doors=2)
    with pytest.raises(ValueError, match="shared"):
        train_policy.Trainer(config, "kitchen", tmp_path, progress=False)
    trainer = train_policy.Trainer(config, train_policy.SHARED, tmp_path, progress=False)
    unrolls = []
    update = trainer._update
    trainer._update = lambda unroll, batch, rng: (unrolls.append(unroll), update(unroll, batch, rng))[1]
    trainer.train()
    T, B, N, K = config.t_max, config.num_envs, len(rooms.GRAPH_NODES), rooms.NUM_ROOM_TYPES
    targets = set()
    for unroll in unrolls:
        assert unroll.obs["node"].shape == (T, B, N) and (unroll.obs["node"].sum(-1) == 1).all()
        assert unroll.aux["room_view"].shape == (T, B, N, nets.VIEW_COLUMNS)
        assert unroll.aux["semantic"].shape == (T, B, K) and unroll.aux["target_distance"].shape == (T, B)
        assert (unroll.aux["target_distance"] >= 0).all()
        # Standing in a typed room, the agent sees some of that room's floor, ceiling or furniture.
        assert unroll.aux["room_view"].any()
        targets |= set(unroll.obs["node"].argmax(-1).ravel().tolist())
    assert len(targets) > 1, "episodes draw their target among the nodes"
    log = policy_eval.read_progress(tmp_path / "shared" / "progress.csv")
    assert np.isfinite(log["aux_loss"]).all() and np.isfinite(log["bc_cross_entropy"]).all()
    train_policy.run_target(config, train_policy.SHARED, tmp_path, progress=False)
    assert not (tmp_path / "kitchen.pt").exists()
    assert policies.folder_targets(tmp_path) == rooms.GRAPH_NODES
    policy = policy_folder.load(str(tmp_path))
    assert policy.nets["kitchen"] is policy.nets["indoor"] and policy.nets["kitchen"].config.target_input


def test_room_view_label_marks_the_strips_showing_each_node():
    from leaps_mj.learning import training_env
    from leaps_mj.world import rooms

    none = len(rooms.GRAPH_NODES)
    nodes = np.full((10, 20), none, np.uint8)
    nodes[:, :4] = rooms.room_index("kitchen")  # the leftmost strip (20 px / 5 strips = 4 px each)
    nodes[0, 19] = rooms.room_index("garage")   # one pixel of 40 in the last strip: 2.5 % >= 2 %
    view = training_env.room_view(nodes)
    assert view.shape == (none, nets.VIEW_COLUMNS)
    assert view[rooms.room_index("kitchen")].tolist() == [1, 0, 0, 0, 0]
    assert view[rooms.room_index("garage")].tolist() == [0, 0, 0, 0, 1]
    assert view.sum() == 2


def test_aux_loss_is_zero_mean_free_and_masks_invalid_steps():
    from leaps_mj.world import rooms

    T, B, N, K = 3, 2, len(rooms.GRAPH_NODES), rooms.NUM_ROOM_TYPES
    labels = {"room_view": torch.randint(0, 2, (T, B, N, nets.VIEW_COLUMNS)),
              "semantic": torch.randint(0, 2, (T, B, K)), "target_distance": torch.full((T, B), 2.5)}
    perfect = {"view": (labels["room_view"].float() * 2 - 1) * 50, "here": (labels["semantic"].float() * 2 - 1) * 50,
               "distance": torch.full((T, B), 2.5 / nets.AUX_DISTANCE_SCALE)}
    valid = torch.ones(T, B)
    loss, scalars = losses.aux_loss(perfect, labels, valid)
    assert loss.item() < 1e-6 and scalars["aux_view_accuracy"] == 1.0 and scalars["aux_distance_error"] < 1e-6
    wrong = dict(perfect, distance=perfect["distance"] + 1.0)
    valid[1:] = 0.0
    wrong["distance"][1:] = 1e3  # masked steps do not count
    loss, scalars = losses.aux_loss(wrong, labels, valid)
    assert loss.item() == pytest.approx(0.5) and scalars["aux_distance_error"] == pytest.approx(nets.AUX_DISTANCE_SCALE)


def test_previous_action_column_is_the_action_taken_one_step_before(tiny_dataset, tmp_path):
    """With prev_action, each step's input is the action the rollout took at the step before
    (-1 at an episode's first step), expert or learner, and the sub-policy feeds its own."""
    from leaps_mj.learning import policies

    config = tiny(tiny_dataset, total_steps=3 * 16, method="dagger", prev_action=True, learner_envs=1)
    trainer = train_policy.Trainer(config, "kitchen", tmp_path, progress=False)
    seen = []
    update = trainer._update
    trainer._update = lambda unroll, batch, rng: (seen.append((unroll, batch)), update(unroll, batch, rng))[1]
    trainer.train()
    for unroll, batch in seen:
        prev, first = unroll.obs["prev_action"].astype(int), unroll.first.astype(bool)
        assert (prev[first] == -1).all()
        inside = ~first[1:]
        np.testing.assert_array_equal(prev[1:][inside], batch["actions"][:-1][inside])
    train_policy.run_target(config, "kitchen", tmp_path, progress=False)
    policy = policies.LearnedSubPolicy(tmp_path, targets=("kitchen",))
    assert policy.nets["kitchen"].config.prev_action


def test_bc_coef_keeps_the_teachers_labels_and_their_loss_in_a2c(tiny_dataset, tmp_path):
    """A2C labels its states with the teacher only when the imitation anchor is on, and logs its cross-entropy."""
    assert not tiny(tiny_dataset, method="a2c").labelled
    config = tiny(tiny_dataset, method="a2c", bc_coef=0.5, total_steps=2 * 16)
    assert config.labelled
    train_policy.Trainer(config, "kitchen", tmp_path, progress=False).train()
    log = policy_eval.read_progress(tmp_path / "kitchen" / "progress.csv")
    assert list(log["phase"]) == ["a2c", "a2c"]
    assert np.isfinite(log["bc_cross_entropy"]).all() and np.isfinite(log["expert_agreement"]).all()
