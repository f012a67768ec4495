"""Tests of leaps_mj.learning.policies: the learned sub-policy behind the SubPolicy interface."""

import numpy as np
import pytest
import torch

import leaps_mj
from leaps_mj.learning import checkpoints, nets, policies
from leaps_mj.planning import agents
from leaps_mj.world import rooms

W, H = 24, 18


@pytest.fixture(scope="module")
def folder(tmp_path_factory):
    """Untrained 24x18 policies for two targets, saved as the trainer saves them."""
    out = tmp_path_factory.mktemp("policies")
    torch.manual_seed(0)
    for target in ("kitchen", "bedroom"):
        config = nets.PolicyConfig(width=W, height=H, conv_channels=(8, 8), hidden=16, lstm=16)
        checkpoints.save_checkpoint(out / f"{target}.pt", nets.ActorCritic(config), config, {"target": target})
    return out


@pytest.fixture(scope="module")
def env(tiny_dataset):
    e = leaps_mj.load(str(tiny_dataset), "train", seed=0, width=W, height=H, targets=("kitchen",), horizon=30)
    yield e
    e.close()


def run(policy, env, spec, steps=12):
    ts = env.reset_to(spec)
    policy.reset(spec.target)
    actions = []
    for _ in range(steps):
        a = policy.act(ts)
        actions.append(a)
        ts = env.step(a)
        if ts.last():
            break
    return actions


def assert_acts_in_a_fresh_env(policy, dataset, width, height):
    """The policy takes 4 valid actions in an environment of the given resolution."""
    env = leaps_mj.load(str(dataset), "train", seed=0, width=width, height=height, horizon=5)
    try:
        env.reset()
        actions = run(policy, env, env.episode, steps=4)
    finally:
        env.close()
    assert actions and all(0 <= a < rooms.NUM_ACTIONS for a in actions)


def test_acts_with_valid_actions_on_a_real_timestep(folder, env):
    policy = policies.LearnedSubPolicy(folder, targets=("kitchen", "bedroom"), seed=3)
    assert isinstance(policy, agents.SubPolicy)
    assert (policy.width, policy.height) == (W, H)
    env.reset()
    actions = run(policy, env, env.episode)
    assert actions and all(isinstance(a, int) and 0 <= a < rooms.NUM_ACTIONS for a in actions)


def test_sampling_is_seeded_and_greedy_is_deterministic(folder, env):
    env.reset()
    spec = env.episode
    sampled = [run(policies.LearnedSubPolicy(folder, targets=("kitchen",), seed=7), env, spec) for _ in range(2)]
    assert sampled[0] == sampled[1]
    greedy = [run(policies.LearnedSubPolicy(folder, targets=("kitchen",), greedy=True), env, spec)
              for _ in range(2)]
    assert greedy[0] == greedy[1]


def test_temperature_sharpens_sampling_towards_greedy(folder, env):
    env.reset()
    spec = env.episode
    greedy = run(policies.LearnedSubPolicy(folder, targets=("kitchen",), greedy=True), env, spec)
    cold = run(policies.LearnedSubPolicy(folder, targets=("kitchen",), seed=7, temperature=1e-7), env, spec)
    assert cold == greedy
    for bad in (0.0, -1.0):
        with pytest.raises(ValueError, match=f"temperature {bad}: expected a positive number"):
            policies.LearnedSubPolicy(folder, targets=("kitchen",), temperature=bad)


def test_reset_clears_the_lstm_state(folder, env):
    policy = policies.LearnedSubPolicy(folder, targets=("kitchen",), greedy=True)
    env.reset()
    spec = env.episode
    first = run(policy, env, spec)
    assert run(policy, env, spec) == first  # same episode, fresh state: same actions


def test_frames_at_a_multiple_of_the_resolution_give_the_same_actions(folder, tiny_dataset, env):
    big = leaps_mj.load(str(tiny_dataset), "train", seed=0, width=3 * W, height=3 * H, targets=("kitchen",),
                        horizon=30)
    try:
        env.reset()
        spec = env.episode
        small_actions = run(policies.LearnedSubPolicy(folder, targets=("kitchen",), greedy=True), env, spec)
        big_actions = run(policies.LearnedSubPolicy(folder, targets=("kitchen",), greedy=True), big, spec)
    finally:
        big.close()
    assert big_actions == small_actions


def test_frames_of_another_size_are_refused(folder, env):
    policy = policies.LearnedSubPolicy(folder, targets=("kitchen",))
    policy.reset("kitchen")
    ts = env.reset()
    obs = dict(ts.observation, segmentation=np.zeros((H, W + 1), np.uint8), depth=np.zeros((H, W + 1), np.float32))
    with pytest.raises(ValueError, match="24x18"):
        policy.act(ts._replace(observation=obs))


def test_wrong_resolution_checkpoint_raises(folder):
    with pytest.raises(ValueError, match="trained at 24x18"):
        policies.LearnedSubPolicy(folder, targets=("kitchen",), width=40, height=30)


def test_missing_target_and_misuse_raise(folder):
    with pytest.raises(ValueError, match="does not exist"):
        policies.LearnedSubPolicy(folder, targets=("garage",))
    policy = policies.LearnedSubPolicy(folder, targets=("kitchen",))
    with pytest.raises(ValueError, match="reset"):
        policy.act(None)
    with pytest.raises(ValueError, match="no sub-policy for target 'bedroom'"):
        policy.reset("bedroom")
    with pytest.raises(ValueError, match="unknown room type|expected one of"):
        policies.LearnedSubPolicy(folder, targets=("attic",))


def test_load_default_names_the_training_command_when_missing(monkeypatch, tmp_path):
    monkeypatch.setattr(policies, "DEFAULT_DIR", tmp_path)
    with pytest.raises(ValueError, match="python -m leaps_mj.train policy --preset cpu"):
        policies.load_default()


def test_every_graph_node_resets_including_the_untyped_hallway():
    policy = policies.load_default()
    for target in rooms.GRAPH_NODES:  # indoor has no one-hot; LEAPS hands it to sub-policies
        policy.reset(target)


def test_load_default_loads_the_shipped_policies(tiny_dataset):
    policy = policies.load_default(seed=0)
    assert (policy.width, policy.height) == (40, 30) and policy.targets == rooms.GRAPH_NODES
    # The cpu preset's 108 k samples continued for 72 k (300 iterations) with starts up to 13 m, evaluated.
    assert all(meta["iteration"] == 300 and meta["global_step"] == 72_000 and meta["eval"]
               and meta["train_config"]["init_from"].endswith("policies/cpu")
               and meta["train_config"]["start_distance"] == 13.0 for meta in policy.metadata.values())
    assert_acts_in_a_fresh_env(policy, tiny_dataset, 120, 90)  # 3x: subsampled


def test_seed_restarts_the_sampler():
    import torch

    from leaps_mj.learning import policies

    sub = policies.load_default()
    sub.seed(5)
    a = torch.rand(3, generator=sub._generator)
    sub.seed(5)
    assert torch.equal(a, torch.rand(3, generator=sub._generator))


@pytest.fixture(scope="module")
def aug_folder(tmp_path_factory):
    """Untrained 24x18 μ_s networks (use_semantic) for two targets."""
    out = tmp_path_factory.mktemp("aug")
    torch.manual_seed(1)
    for target in ("kitchen", "bedroom"):
        config = nets.PolicyConfig(width=W, height=H, conv_channels=(8, 8), hidden=16, lstm=16, use_semantic=True)
        checkpoints.save_checkpoint(out / f"{target}.pt", nets.ActorCritic(config), config, {"target": target})
    return out


def test_mu_s_reads_the_bits_and_the_one_hot_of_its_own_target(aug_folder, env):
    policy = policies.LearnedSubPolicy(aug_folder, targets=("kitchen", "bedroom"), seed=0, use_semantic=True)
    seen = []
    net = policy.nets["bedroom"]
    original = net.forward

    def spy(obs, state, done_mask=None):
        seen.append({k: v.clone() for k, v in obs.items()})
        return original(obs, state, done_mask)

    net.forward = spy
    ts = env.reset()  # the environment's target is kitchen; the policy runs towards bedroom
    policy.reset("bedroom")
    bits = []
    for _ in range(5):
        bits.append(np.asarray(ts.observation["semantic"], np.float32))
        ts = env.step(policy.act(ts))
    assert len(seen) == 5
    target = np.zeros(rooms.NUM_ROOM_TYPES, np.float32)
    target[rooms.room_index("bedroom")] = 1
    for obs, expected in zip(seen, bits):
        assert set(obs) == {"segmentation", "depth", "semantic", "target"}
        np.testing.assert_array_equal(obs["target"].numpy(), target[None])
        np.testing.assert_array_equal(obs["semantic"].numpy(), expected[None])
    assert any(b.any() for b in bits), "the start room is typed: some bit is on"


def test_pixel_and_semantic_policies_are_not_confused(folder, aug_folder):
    with pytest.raises(ValueError, match="semantic-augmented"):
        policies.LearnedSubPolicy(folder, targets=("kitchen",), use_semantic=True)
    with pytest.raises(ValueError, match="pixel-only"):
        policies.LearnedSubPolicy(aug_folder, targets=("kitchen",))


def test_load_augmented_loads_the_shipped_mu_s(tiny_dataset):
    policy = policies.load_augmented(seed=0)
    assert (policy.width, policy.height) == (40, 30) and policy.targets == rooms.ROOM_TYPES
    assert policy.use_semantic and all(meta["eval"] for meta in policy.metadata.values())
    assert_acts_in_a_fresh_env(policy, tiny_dataset, 40, 30)


def test_load_augmented_names_the_training_command_when_missing(monkeypatch, tmp_path):
    monkeypatch.setattr(policies, "AUGMENTED_DIR", tmp_path)
    with pytest.raises(ValueError, match="--use-semantic true"):
        policies.load_augmented()
