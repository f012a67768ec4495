"""Tests for the baselines: the controller agent, the augmented-policy agent, and the controller trainer."""

import dataclasses

import dm_env
import numpy as np
import pytest
import torch

from leaps_mj.learning import baselines, checkpoints, nets, train_controller
from leaps_mj.world import rooms

K = rooms.NUM_ROOM_TYPES


class FakeSubPolicy:
    """Records its resets and the time steps it acted on."""

    def __init__(self):
        self.resets, self.seen = [], []

    def reset(self, target):
        self.resets.append(target)

    def act(self, timestep):
        self.seen.append(timestep)
        return 8


def timestep(*where, target="outdoor"):
    bits = np.zeros(K, dtype=np.uint8)
    for name in where:
        bits[rooms.room_index(name)] = 1
    return dm_env.transition(0.0, {"semantic": bits, "target": np.eye(K, dtype=np.uint8)[rooms.room_index(target)]})


def fixed_choice_net(room_type):
    """A controller whose logits always favour ``room_type``."""
    net = nets.ControllerNet()
    with torch.no_grad():
        net.policy.weight.zero_()
        net.policy.bias.copy_(torch.as_tensor(10.0 * np.eye(K)[rooms.room_index(room_type)]))
    return net


def test_controller_inputs_layout():
    x = baselines.controller_inputs(np.eye(K)[1], np.eye(K)[1] + np.eye(K)[2], 0, 5)
    assert x.shape == (32,) and x.dtype == np.float32
    assert np.flatnonzero(x).tolist() == [1, K + 1, K + 2, 2 * K + 0, 3 * K + 5]
    assert baselines.controller_inputs(np.zeros(K), np.zeros(K), 3, None)[3 * K:].sum() == 0


def test_controller_picks_a_subtarget_every_n_steps():
    sub = FakeSubPolicy()
    agent = baselines.ControllerAgent(sub, fixed_choice_net("kitchen"), option_steps=5, greedy=True)
    agent.reset("outdoor")
    for _ in range(12):
        assert agent.step(timestep("bedroom")) == 8
    assert [(d.step, d.reason) for d in agent.decisions] == [(0, "start"), (5, "option"), (10, "option")]
    assert [d.subtarget for d in agent.decisions] == [rooms.room_index("kitchen")] * 3
    assert sub.resets == ["kitchen"]  # the same sub-target keeps its run going
    assert len(sub.seen) == 12 and agent.info() == {"subtarget": "kitchen", "plan": [], "belief": None}
    first, second = agent.decisions[0].inputs, agent.decisions[1].inputs
    assert first[3 * K:].sum() == 0 and second[3 * K + rooms.room_index("kitchen")] == 1
    assert second[K + rooms.room_index("bedroom")] == 1 and second[2 * K + rooms.room_index("outdoor")] == 1


def test_controller_decides_again_when_it_enters_the_subtarget_room():
    sub = FakeSubPolicy()
    agent = baselines.ControllerAgent(sub, fixed_choice_net("kitchen"), option_steps=30, greedy=True)
    agent.reset("outdoor")
    for where in [("bedroom",)] * 3 + [("kitchen",)] * 4:
        agent.step(timestep(*where))
    assert [(d.step, d.reason) for d in agent.decisions] == [(0, "start"), (3, "reached")]
    agent.reset("garage")
    agent.step(timestep("kitchen", target="garage"))
    assert [d.reason for d in agent.decisions] == ["start"]
    for _ in range(5):  # already in the sub-target's room when the option began: no new decision
        agent.step(timestep("kitchen", target="garage"))
    assert len(agent.decisions) == 1


def test_controller_samples_from_its_seed():
    def choices(seed):
        agent = baselines.ControllerAgent(FakeSubPolicy(), nets.ControllerNet(), option_steps=1, seed=seed)
        agent.reset("garage")
        for _ in range(20):
            agent.step(timestep(target="garage"))
        return [d.subtarget for d in agent.decisions]

    assert choices(1) == choices(1) and choices(1) != choices(2) and len(set(choices(1))) > 1


def test_controller_rejects_bad_input():
    with pytest.raises(ValueError, match="option_steps"):
        baselines.ControllerAgent(FakeSubPolicy(), nets.ControllerNet(), option_steps=0)
    with pytest.raises(ValueError, match="ControllerNet"):
        baselines.ControllerAgent(FakeSubPolicy(), nets.RoomClassifier(nets.RoomClassifierConfig()))
    agent = baselines.ControllerAgent(FakeSubPolicy(), nets.ControllerNet())
    with pytest.raises(ValueError, match="before reset"):
        agent.step(timestep())
    with pytest.raises(ValueError, match="unknown target"):
        agent.reset("attic")


def test_augmented_agent_runs_mu_s_on_the_whole_timestep():
    sub = FakeSubPolicy()
    agent = baselines.AugmentedPolicyAgent(sub)
    agent.reset("bedroom")
    steps = [timestep("kitchen", target="bedroom"), timestep("bedroom", target="bedroom")]
    assert [agent.step(ts) for ts in steps] == [8, 8]
    assert agent.name == "aug" and sub.resets == ["bedroom"] and sub.seen == steps
    assert agent.info()["subtarget"] == "bedroom"


def test_controller_checkpoint_round_trip(tmp_path):
    net = fixed_choice_net("garage")
    checkpoints.save_checkpoint(tmp_path / "c.pt", net, net.config, {"option_steps": 7, "subpolicy": "local"})
    agent = baselines.ControllerAgent.from_checkpoint(FakeSubPolicy(), tmp_path / "c.pt", greedy=True)
    assert agent.option_steps == 7
    agent.reset("outdoor")
    agent.step(timestep())
    assert agent.info()["subtarget"] == "garage"
    checkpoints.save_checkpoint(tmp_path / "bare.pt", net, net.config)
    with pytest.raises(ValueError, match="not a controller checkpoint"):
        baselines.load_controller(tmp_path / "bare.pt")
    with pytest.raises(ValueError, match="no controller checkpoint"):
        baselines.load_controller(tmp_path / "missing.pt")
    assert nets.ControllerNet().num_parameters() == 17_259


def test_discounted_returns():
    r = train_controller.discounted_returns(np.array([-0.1, -0.1, 1.9]), 0.5)
    np.testing.assert_allclose(r, [-0.1 - 0.05 + 1.9 / 4, -0.1 + 1.9 / 2, 1.9])


def test_a2c_update_favours_the_rewarded_choice():
    torch.manual_seed(0)
    net = nets.ControllerNet()
    config = train_controller.PRESETS["tiny"]
    x = baselines.controller_inputs(np.zeros(K), np.zeros(K), 2, None)[None]
    good = {"inputs": x, "choices": np.array([2]), "rewards": np.array([1.9])}
    bad = {"inputs": x, "choices": np.array([5]), "rewards": np.array([-0.1])}
    optimizer = torch.optim.Adam(net.parameters(), lr=1e-2)
    before = torch.softmax(net(torch.as_tensor(x), net.initial_state(1))[0], -1)[0]
    for _ in range(20):
        loss, scalars = train_controller.a2c_loss(net, [good, bad], config)
        optimizer.zero_grad()
        loss.backward()
        optimizer.step()
    after = torch.softmax(net(torch.as_tensor(x), net.initial_state(1))[0], -1)[0]
    assert after[2] > before[2] + 0.1 and after[5] < before[5]
    assert set(scalars) == {"policy_loss", "value_loss", "entropy"}


def test_tiny_controller_trainer_saves_resumes_and_validates(tiny_dataset, tmp_path):
    config = dataclasses.replace(train_controller.PRESETS["tiny"], dataset=str(tiny_dataset))
    first = train_controller.Trainer(config, tmp_path, progress=False)
    first.train(stop_after=1)
    assert first.iteration == 1 and not first.finished
    second = train_controller.Trainer(config, tmp_path, progress=False)
    assert second.update == 1
    second.train()
    assert second.finished and [r["update"] for r in second.history] == [1, 2]
    result = second.validate()
    assert result["episodes"] == 2 and 0.0 <= result["controller_success"] <= 1.0
    net, extra = baselines.load_controller(tmp_path / "controller.pt")
    assert extra["option_steps"] == config.option_steps and extra["subpolicy"] == "local"
    assert (tmp_path / "progress.csv").read_text().count("\n") == 3
    with pytest.raises(ValueError, match="another configuration"):
        train_controller.Trainer(dataclasses.replace(config, lr=0.5), tmp_path, progress=False)
    with pytest.raises(ValueError, match="another configuration"):  # a run cannot shrink
        train_controller.Trainer(dataclasses.replace(config, episodes=2), tmp_path, progress=False)
    extended = train_controller.Trainer(dataclasses.replace(config, episodes=6), tmp_path, progress=False)
    assert extended.update == 2 and not extended.finished
    extended.train()
    assert extended.finished and [r["update"] for r in extended.history] == [1, 2, 3]
    with pytest.raises(ValueError, match="subpolicy"):
        train_controller.resolve_subpolicy("best")


def test_controller_trains_over_the_map_goal_sub_policy_of_a_folder(tiny_dataset, tmp_path, capsys):
    from leaps_mj.learning import goal_policy

    argv = ["--preset", "tiny", "--dataset", str(tiny_dataset), "--out", str(tmp_path), "--no-progress",
            "--policy-dir", str(goal_policy.DEFAULT_DIR)]
    assert train_controller.main(argv) == 0
    assert "sub-policy learned" in capsys.readouterr().out
    config = dataclasses.replace(train_controller.PRESETS["tiny"], dataset=str(tiny_dataset), subpolicy="learned",
                                 policy_dir=str(goal_policy.DEFAULT_DIR))
    assert train_controller.Trainer(config, tmp_path, progress=False).finished  # the run's config: this folder's
    with pytest.raises(ValueError, match="another configuration"):
        train_controller.Trainer(dataclasses.replace(config, policy_dir=None), tmp_path, progress=False)
    assert isinstance(train_controller.make_subpolicy(config, None, 0), goal_policy.GoalSubPolicy)
    with pytest.raises(ValueError, match="policy_dir 'x' needs subpolicy 'learned'"):
        dataclasses.replace(config, subpolicy="local", policy_dir="x")


def test_a_policy_folder_brings_its_own_controller(tmp_path):
    from leaps_mj.evaluation import registry
    from leaps_mj.learning import policy_folder

    assert policy_folder.controller_path(None) == baselines.DEFAULT_CONTROLLER
    assert policy_folder.controller_path(tmp_path) == baselines.DEFAULT_CONTROLLER  # none of its own
    net = fixed_choice_net("garage")
    checkpoints.save_checkpoint(tmp_path / policy_folder.CONTROLLER, net, net.config, {"option_steps": 5, "subpolicy": "learned"})
    assert policy_folder.controller_path(tmp_path) == tmp_path / policy_folder.CONTROLLER
    agent = registry.make_agent("controller", None, subpolicy=FakeSubPolicy(),
                                controller=policy_folder.controller_path(tmp_path))
    assert agent.option_steps == 5
    with pytest.raises(ValueError, match="takes no options"):
        registry.make_agent("pure", None, subpolicy=FakeSubPolicy(), controller=tmp_path)
