"""Tests of leaps_mj.learning.nets: shapes, step/sequence equivalence, checkpoints."""

import numpy as np
import pytest
import torch

from leaps_mj.learning import checkpoints, nets
from leaps_mj.world import rooms

W, H = 40, 30
K = rooms.NUM_ROOM_TYPES
SMALL = dict(width=W, height=H, conv_channels=(8, 8, 16, 16), hidden=32, lstm=32)


@pytest.fixture(autouse=True)
def _seed():
    torch.manual_seed(0)


def random_obs(lead, width=W, height=H, seed=0):
    """Numpy observations with leading dims ``lead`` as the environment gives them."""
    rng = np.random.default_rng(seed)
    onehot = np.eye(K, dtype=np.float32)[rng.integers(0, K, size=lead)]
    return {
        "segmentation": rng.integers(0, rooms.NUM_SEG_CLASSES, size=(*lead, height, width), dtype=np.int32),
        "depth": rng.uniform(0.0, 15.0, size=(*lead, height, width)).astype(np.float32),
        "semantic": rng.integers(0, 2, size=(*lead, K)).astype(np.float32),
        "target": onehot,
        "node": np.eye(K + 1, dtype=np.float32)[rng.integers(0, K + 1, size=lead)],
    }


def small_policy(**overrides):
    return nets.ActorCritic(nets.PolicyConfig(**{**SMALL, **overrides}))


@pytest.mark.parametrize("use_semantic", [False, True])
@pytest.mark.parametrize("seg_embed", [0, 8])
def test_step_and_sequence_shapes(use_semantic, seg_embed):
    model = small_policy(use_semantic=use_semantic, seg_embed=seg_embed)
    obs = nets.ActorCritic.preprocess(random_obs((3,)))
    logits, value, (h, c) = model(obs, model.initial_state(3))
    assert logits.shape == (3, rooms.NUM_ACTIONS) and value.shape == (3,)
    assert h.shape == c.shape == (3, 32)
    seq = nets.ActorCritic.preprocess(random_obs((5, 3)))
    logits, values, (h, c) = model.forward_sequence(seq, model.initial_state(3), torch.zeros(5, 3))
    assert logits.shape == (5, 3, rooms.NUM_ACTIONS) and values.shape == (5, 3)
    assert h.shape == (3, 32)


@pytest.mark.parametrize("use_semantic", [False, True])
def test_sequence_equals_stepping_with_reset(use_semantic):
    model = small_policy(use_semantic=use_semantic)
    steps, batch = 6, 3
    seq = nets.ActorCritic.preprocess(random_obs((steps, batch)))
    dones = torch.zeros(steps, batch)
    dones[3, 1] = 1.0  # an episode begins mid-unroll in env 1
    start = tuple(torch.randn(batch, 32) for _ in range(2))
    with torch.no_grad():
        seq_logits, seq_values, seq_state = model.forward_sequence(seq, start, dones)
        state = start
        for t in range(steps):
            logits, value, state = model({k: v[t] for k, v in seq.items()}, state, dones[t])
            torch.testing.assert_close(logits, seq_logits[t], atol=1e-5, rtol=0)
            torch.testing.assert_close(value, seq_values[t], atol=1e-5, rtol=0)
    for a, b in zip(state, seq_state):
        torch.testing.assert_close(a, b, atol=1e-5, rtol=0)


def test_done_mask_zeroes_state():
    model = small_policy()
    obs = nets.ActorCritic.preprocess(random_obs((2,)))
    state = tuple(torch.randn(2, 32) for _ in range(2))
    with torch.no_grad():
        reset, _, _ = model(obs, state, torch.tensor([1.0, 0.0]))
        fresh, _, _ = model(obs, model.initial_state(2))
        kept, _, _ = model(obs, state)
    torch.testing.assert_close(reset[0], fresh[0])
    torch.testing.assert_close(reset[1], kept[1])
    assert not torch.allclose(reset[0], kept[0])


def test_semantic_inputs_change_output_and_are_required():
    model = small_policy(use_semantic=True)
    obs = nets.ActorCritic.preprocess(random_obs((2,)))
    with torch.no_grad():
        a, _, _ = model(obs, model.initial_state(2))
        b, _, _ = model({**obs, "target": obs["target"].roll(1, dims=1)}, model.initial_state(2))
    assert not torch.allclose(a, b)
    with pytest.raises(ValueError, match="target"):
        model({k: v for k, v in obs.items() if k != "target"}, model.initial_state(2))
    with pytest.raises(ValueError, match="semantic"):
        model({**obs, "semantic": torch.zeros(2, K + 1)}, model.initial_state(2))


def test_shared_network_reads_the_node_and_steps_like_its_sequence():
    """A target_input net: the node one-hot changes the action and is required; stepping equals the
    unroll; the auxiliary heads have the documented shapes and exist only with aux."""
    model = small_policy(target_input=True, aux=True)
    steps, batch = 4, 3
    seq = nets.ActorCritic.preprocess(random_obs((steps, batch)))
    assert model.input_keys() == ("segmentation", "depth", "node")
    with torch.no_grad():
        out = model.unroll(seq, model.initial_state(batch), torch.zeros(steps, batch))
        state = model.initial_state(batch)
        for t in range(steps):
            logits, value, state = model({k: v[t] for k, v in seq.items()}, state)
            torch.testing.assert_close(logits, out["logits"][t], atol=1e-5, rtol=0)
        other, _, _ = model({**{k: v[0] for k, v in seq.items()}, "node": seq["node"][0].roll(1, dims=1)},
                            model.initial_state(batch))
        assert not torch.allclose(other, out["logits"][0])
        aux = model.aux_outputs(out)
    assert aux["view"].shape == (steps, batch, K + 1, nets.VIEW_COLUMNS)
    assert aux["here"].shape == (steps, batch, K) and aux["distance"].shape == (steps, batch)
    with pytest.raises(ValueError, match="node"):
        model({k: v[0] for k, v in seq.items() if k != "node"}, model.initial_state(batch))
    with pytest.raises(ValueError, match="no auxiliary heads"):
        small_policy().aux_outputs(out)


def test_previous_action_input_changes_the_output_and_is_checked():
    model = small_policy(prev_action=True)
    obs = nets.ActorCritic.preprocess({**random_obs((2,)), "prev_action": np.array([-1, 3])})
    assert obs["prev_action"].dtype == torch.long and model.input_keys()[-1] == "prev_action"
    with torch.no_grad():
        a, _, _ = model(obs, model.initial_state(2))
        b, _, _ = model({**obs, "prev_action": torch.tensor([4, 3])}, model.initial_state(2))
    assert not torch.allclose(a[0], b[0]) and torch.allclose(a[1], b[1])
    with pytest.raises(ValueError, match="prev_action has shape"):
        model({**obs, "prev_action": torch.zeros(2, 1, dtype=torch.long)}, model.initial_state(2))
    with pytest.raises(ValueError, match="prev_action"):
        model({k: v for k, v in obs.items() if k != "prev_action"}, model.initial_state(2))


def test_bad_inputs_raise_value_error():
    model = small_policy()
    with pytest.raises(ValueError, match="40x30"):
        model(nets.ActorCritic.preprocess(random_obs((2,), width=64, height=48)), model.initial_state(2))
    obs = random_obs((2,))
    obs["segmentation"][0, 0, 0] = rooms.NUM_SEG_CLASSES
    with pytest.raises(ValueError, match="segmentation ids"):
        nets.ActorCritic.preprocess(obs)
    with pytest.raises(ValueError, match="dones"):
        model.forward_sequence(nets.ActorCritic.preprocess(random_obs((4, 2))), model.initial_state(2), torch.zeros(4))


@pytest.mark.parametrize(
    "field, value",
    [("width", 0), ("conv_channels", ()), ("conv_channels", (8, -1)), ("seg_embed", -1), ("max_depth", 0.0)],
)
def test_policy_config_rejects_bad_values(field, value):
    with pytest.raises(ValueError, match=field):
        nets.PolicyConfig(**{field: value})


def test_classifier_shapes_and_attention():
    model = nets.RoomClassifier(nets.RoomClassifierConfig(width=W, height=H))
    rng = np.random.default_rng(1)
    seg = torch.as_tensor(rng.integers(0, rooms.NUM_SEG_CLASSES, size=(2, 4, H, W)))
    depth = torch.as_tensor(rng.uniform(0, 12, size=(2, 4, H, W)), dtype=torch.float32)
    logits = model(seg, depth)
    assert logits.shape == (2, K)
    pooled, weights = model.attend(seg, depth)
    assert pooled.shape == (2, 256) and weights.shape == (2, 4)
    torch.testing.assert_close(weights.sum(dim=1), torch.ones(2))
    with pytest.raises(ValueError, match="seg"):
        model(seg[:, :3], depth[:, :3])
    with pytest.raises(ValueError, match="strides"):
        nets.RoomClassifierConfig(strides=(1, 2))


def test_controller_shapes_and_parameter_count():
    model = nets.ControllerNet()
    logits, value, (h, c) = model(torch.zeros(3, 4 * K), model.initial_state(3))
    assert logits.shape == (3, K) and value.shape == (3,) and h.shape == c.shape == (3, 50)
    lstm = 4 * 50 * (4 * K + 50) + 2 * 4 * 50
    assert model.num_parameters() == lstm + (50 * K + K) + (50 + 1) == 17259
    semantic_model = 9 * 8 // 2 + 2  # edge probabilities of the 9-node graph + 2 noise rates
    assert semantic_model == 38 and model.num_parameters() > 400 * semantic_model
    with pytest.raises(ValueError, match="32"):
        model(torch.zeros(3, 30), model.initial_state(3))


@pytest.mark.parametrize(
    "config",
    [
        nets.PolicyConfig(**SMALL, use_semantic=True),
        nets.RoomClassifierConfig(width=W, height=H, channels=(4, 8, 16), strides=(1, 2, 2)),
        nets.ControllerConfig(),
    ],
    ids=lambda c: type(c).__name__,
)
def test_checkpoint_round_trip(tmp_path, config):
    model = checkpoints._NETS[type(config).__name__][1](config).eval()
    path = tmp_path / "sub" / "ckpt.pt"
    checkpoints.save_checkpoint(path, model, config, {"step": 7, "target": "kitchen", "curve": [1.0, 2.0]})
    loaded, loaded_config, extra = checkpoints.load_policy(path, expect_width=W, expect_height=H)
    assert loaded_config == config and extra == {"step": 7, "target": "kitchen", "curve": [1.0, 2.0]}
    assert [p.name for p in path.parent.iterdir()] == ["ckpt.pt"]  # no temp file left behind
    with torch.no_grad():
        if isinstance(model, nets.ActorCritic):
            obs = nets.ActorCritic.preprocess(random_obs((2,)))
            pairs = [(model(obs, model.initial_state(2))[0], loaded(obs, loaded.initial_state(2))[0])]
        elif isinstance(model, nets.RoomClassifier):
            seg = torch.randint(0, rooms.NUM_SEG_CLASSES, (2, 4, H, W))
            depth = torch.rand(2, 4, H, W) * 10
            pairs = [(model(seg, depth), loaded(seg, depth))]
        else:
            x = torch.rand(2, 4 * K)
            pairs = [(model(x, model.initial_state(2))[0], loaded(x, loaded.initial_state(2))[0])]
    for a, b in pairs:
        assert torch.equal(a, b)


def test_load_rejects_wrong_resolution(tmp_path):
    path = tmp_path / "policy.pt"
    model = small_policy()
    checkpoints.save_checkpoint(path, model, model.config, {})
    with pytest.raises(ValueError, match="40x30") as info:
        checkpoints.load_policy(path, expect_width=64, expect_height=48)
    assert "64x48" in str(info.value) and "policy.pt" in str(info.value)


def test_load_rejects_other_class_table(tmp_path):
    path = tmp_path / "policy.pt"
    model = small_policy()
    checkpoints.save_checkpoint(path, model, model.config, {})
    payload = torch.load(path, weights_only=True)
    payload["seg_classes"] = payload["seg_classes"][:-1]
    torch.save(payload, path)
    with pytest.raises(ValueError, match="segmentation classes"):
        checkpoints.load_policy(path)


def test_load_rejects_missing_and_corrupt_files(tmp_path):
    with pytest.raises(ValueError, match="nothing.pt"):
        checkpoints.load_policy(tmp_path / "nothing.pt")
    garbage = tmp_path / "garbage.pt"
    garbage.write_bytes(b"not a checkpoint at all")
    with pytest.raises(ValueError, match="garbage.pt"):
        checkpoints.load_policy(garbage)
    path = tmp_path / "truncated.pt"
    model = small_policy()
    checkpoints.save_checkpoint(path, model, model.config, {})
    path.write_bytes(path.read_bytes()[:1000])
    with pytest.raises(ValueError, match="truncated.pt"):
        checkpoints.load_policy(path)


def test_save_rejects_bad_arguments(tmp_path):
    model = small_policy()
    with pytest.raises(ValueError, match=r"extra\['arr'\]"):
        checkpoints.save_checkpoint(tmp_path / "a.pt", model, model.config, {"arr": np.zeros(3)})
    with pytest.raises(ValueError, match="differs"):
        checkpoints.save_checkpoint(tmp_path / "a.pt", model, nets.PolicyConfig(**{**SMALL, "hidden": 64}), {})
    assert not list(tmp_path.iterdir())


def test_paper_size_policy_builds_and_runs():
    model = nets.ActorCritic(nets.PolicyConfig())
    count = model.num_parameters()
    assert 500_000 < count < 5_000_000, f"paper-size ActorCritic has {count:,} parameters"
    with torch.no_grad():
        logits, value, _ = model(nets.ActorCritic.preprocess(random_obs((1,), 120, 90)), model.initial_state(1))
    assert logits.shape == (1, rooms.NUM_ACTIONS) and value.shape == (1,)


def test_map_input_is_read_bypasses_the_lstm_and_is_checked():
    from leaps_mj.environment import mapping

    model = small_policy(map_input=True)
    shape = (len(mapping.CHANNELS), mapping.WINDOW, mapping.WINDOW)
    rng = np.random.default_rng(1)
    steps, batch = 3, 2
    seq = nets.ActorCritic.preprocess({**random_obs((steps, batch)),
                                       "egomap": rng.integers(0, 2, (steps, batch, *shape), dtype=np.uint8)})
    assert model.input_keys()[-1] == "egomap" and seq["egomap"].dtype == torch.float32
    with torch.no_grad():
        out = model.unroll(seq, model.initial_state(batch), torch.zeros(steps, batch))
        state = model.initial_state(batch)
        for t in range(steps):
            logits, _, state = model({k: v[t] for k, v in seq.items()}, state)
            torch.testing.assert_close(logits, out["logits"][t], atol=1e-5, rtol=0)
        step0 = {k: v[0] for k, v in seq.items()}
        flipped, _, _ = model({**step0, "egomap": 1.0 - step0["egomap"]}, model.initial_state(batch))
    assert not torch.allclose(flipped, out["logits"][0])
    assert out["head"].shape[-1] == 32 + nets.MAP_HIDDEN
    with pytest.raises(ValueError, match="egomap has shape"):
        model({**step0, "egomap": step0["egomap"][:, :, :8]}, model.initial_state(batch))
    with pytest.raises(ValueError, match="egomap"):
        model({k: v for k, v in step0.items() if k != "egomap"}, model.initial_state(batch))
