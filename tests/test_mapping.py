"""Tests of leaps_mj.environment.mapping: the egocentric map built from frames and pose."""

import dataclasses
import math

import numpy as np
import pytest
import torch

import leaps_mj
from leaps_mj.environment import mapping
from leaps_mj.learning import checkpoints, nets, policies, training_env
from leaps_mj.learning.policy_config import PRESETS
from leaps_mj.world import rooms

W, H = 40, 30
WALL = rooms.seg_class_index("wall")
SINK = rooms.seg_class_index("sink")  # a kitchen see-object
EMPTY = rooms.seg_class_index("empty")
MID = mapping.WINDOW // 2


def channel(name):
    return mapping.CHANNELS.index(name)


def wall_frame(distance=2.0):
    return np.full((H, W), WALL, np.uint8), np.full((H, W), distance, np.float32)


def test_a_wall_ahead_lies_ahead_in_the_window_whatever_the_heading():
    mapper = mapping.EgoMapper("kitchen", W, H)
    seg, depth = wall_frame(2.0)
    window = mapper.update(seg, depth, (1.0, -3.0, 0.0))
    rows, cols = np.nonzero(window[channel("obstacle")])
    # 2 m ahead = 8 cells above the agent, across the 60° x 77° view (about ±1.6 m, ±6-7 cells).
    assert set(rows) <= {MID - 9, MID - 8} and cols.min() >= MID - 7 and cols.max() <= MID + 6
    assert not window[[channel("floor"), channel("door"), channel("target")]].any()
    for yaw in (math.pi / 2, -2.0):
        mapper.reset()
        turned = mapper.update(seg, depth, (1.0, -3.0, yaw))
        agree = (turned[channel("obstacle")] == window[channel("obstacle")]).mean()
        assert agree > 0.97, yaw


def test_the_target_to_the_left_of_the_frame_is_left_of_the_agent_and_remembered_behind():
    mapper = mapping.EgoMapper("kitchen", W, H)
    seg, depth = wall_frame(3.0)
    seg[:, : W // 2] = SINK
    window = mapper.update(seg, depth, (0.0, 0.0, 0.3))
    _, cols = np.nonzero(window[channel("target")])
    assert len(cols) and cols.max() < MID
    # Turned around, seeing nothing: the sink is now behind, on the right.
    nothing = np.full((H, W), EMPTY, np.uint8)
    window = mapper.update(nothing, depth, (0.0, 0.0, 0.3 + math.pi))
    rows, cols = np.nonzero(window[channel("target")])
    assert len(rows) and rows.min() > MID and cols.min() >= MID
    # The bedroom's mapper counts the sink as furniture, not as its target.
    other = mapping.EgoMapper("bedroom", W, H).update(seg, depth, (0.0, 0.0, 0.3))
    assert not other[channel("target")].any() and other[channel("furniture")].any()


def test_heights_decide_obstacles_and_the_ceiling_is_not_mapped():
    mapper = mapping.EgoMapper("kitchen", W, H)
    seg, depth = wall_frame(2.0)
    window = mapper.update(seg, depth, (0.0, 0.0, 0.0))
    # The top rows of a wall 2 m away are above 2 m: only part of the frame is mapped.
    assert window[channel("obstacle")].sum() < 2 * W
    seg[:] = rooms.seg_class_index("ceiling")
    mapper.reset()
    assert not mapper.update(seg, depth, (0.0, 0.0, 0.0))[:channel("visited")].any()


def test_visited_cells_follow_the_agent_and_reset_forgets():
    mapper = mapping.EgoMapper("indoor", W, H)
    nothing = np.full((H, W), EMPTY, np.uint8)
    depth = np.ones((H, W), np.float32)
    mapper.update(nothing, depth, (5.0, 5.0, 0.0))
    window = mapper.update(nothing, depth, (6.0, 5.0, 0.0))  # 1 m forward
    # The agent's cell is just ahead-left of the window's centre; the start 1 m (4 cells) behind it.
    assert set(zip(*np.nonzero(window[channel("visited")]))) == {(MID - 1, MID - 1), (MID + 3, MID - 1)}
    mapper.reset()
    window = mapper.update(nothing, depth, (6.0, 5.0, 0.0))
    assert window[channel("visited")].sum() == 1


def test_bad_input_names_what_was_expected():
    with pytest.raises(ValueError, match="unknown room type|expected one of"):
        mapping.EgoMapper("attic", W, H)
    with pytest.raises(ValueError, match="expected positive"):
        mapping.EgoMapper("kitchen", 0, H)
    mapper = mapping.EgoMapper("kitchen", W, H)
    with pytest.raises(ValueError, match=r"\(height, width\) = \(30, 40\)"):
        mapper.update(np.zeros((H, W + 1), np.uint8), np.zeros((H, W + 1)), (0.0, 0.0, 0.0))


def test_the_camera_model_is_the_environments(tiny_dataset):
    env = leaps_mj.load(str(tiny_dataset), "train", seed=0, width=W, height=H)
    try:
        assert float(env.physics.model.cam_fovy[0]) == mapping.CAMERA_FOVY
        assert float(env.physics.model.cam_pos[0][2]) == rooms.AGENT_CAMERA_HEIGHT
    finally:
        env.close()


def test_training_env_and_sub_policy_build_the_same_maps(tiny_dataset, tmp_path):
    """The map a policy reads in training (built in the worker) is the one it builds itself when evaluated."""
    config = dataclasses.replace(PRESETS["tiny"], dataset=str(tiny_dataset), width=W, height=H, map_input=True)
    torch.manual_seed(0)
    net_config = config.policy_config()
    checkpoints.save_checkpoint(tmp_path / "kitchen.pt", nets.ActorCritic(net_config), net_config, {"target": "kitchen"})
    policy = policies.LearnedSubPolicy(tmp_path, targets=("kitchen",))
    seen = []
    net = policy.nets["kitchen"]
    forward = net.forward
    net.forward = lambda obs, state, done_mask=None: (seen.append(obs["egomap"][0].numpy()),
                                                      forward(obs, state, done_mask))[1]

    def make():
        return leaps_mj.load(str(tiny_dataset), "train", seed=0, width=W, height=H, targets=("kitchen",))

    train_env = training_env.TrainingEnv(make(), config, 0, seed=0, label=False)
    eval_env = make()
    try:
        ts = train_env.reset()
        spec = train_env.episode
        actions = [3, 3, 0, 0, 4, 0, 1, 3, 0]
        maps = [ts.observation["egomap"]]
        for a in actions:
            maps.append(train_env.step(a).observation["egomap"])
        ets = eval_env.reset_to(spec)
        policy.reset("kitchen")
        for a in actions + [0]:
            policy.act(ets)
            ets = eval_env.step(a)
    finally:
        train_env.close()
        eval_env.close()
    assert len(seen) == len(maps)
    for built, trained in zip(seen, maps):
        np.testing.assert_array_equal(built, trained)
    assert maps[-1][channel("visited")].sum() >= 2 and maps[-1][channel("floor")].any()


def test_the_context_window_sees_twice_as_far_at_half_the_resolution():
    mapper = mapping.EgoMapper("kitchen", W, H)
    seg, depth = wall_frame(6.0)  # 6 m ahead: beyond the fine window's 4 m, inside the coarse one's 8 m
    window = mapper.update(seg, depth, (0.5, 2.0, 1.1))
    context = mapper.context((0.5, 2.0, 1.1))
    assert context.shape == window.shape and context.dtype == np.uint8
    assert not window[channel("obstacle")].any()
    rows, cols = np.nonzero(context[channel("obstacle")])
    # 6 m ahead = 12 coarse cells above the agent; the view's ±4.6 m across are ±9-10 coarse cells.
    assert set(rows) <= {MID - 13, MID - 12} and cols.min() >= MID - 10 and cols.max() <= MID + 9
    # A wall 2 m ahead fills fine cells and the coarse cells covering them, at half the distance.
    mapper.reset()
    seg, depth = wall_frame(2.0)
    window = mapper.update(seg, depth, (0.0, 0.0, 0.0))
    context = mapper.context((0.0, 0.0, 0.0))
    fine_rows = set(np.nonzero(window[channel("obstacle")])[0])
    coarse_rows = set(np.nonzero(context[channel("obstacle")])[0])
    assert coarse_rows == {MID - (MID - r + 1) // 2 for r in fine_rows}


def test_cues_mark_the_outdoor_fences_and_trees_as_its_target():
    seg, depth = wall_frame(2.0)
    seg[:, : W // 2] = rooms.seg_class_index("fence")
    seg[:, W // 2:] = rooms.seg_class_index("tree")
    plain = mapping.EgoMapper("outdoor", W, H).update(seg, depth, (0.0, 0.0, 0.0))
    cued = mapping.EgoMapper("outdoor", W, H, cues=True).update(seg, depth, (0.0, 0.0, 0.0))
    assert not plain[channel("target")].any() and plain[channel("obstacle")].any()
    assert cued[channel("target")].any() and not cued[channel("obstacle")].any()
    # Other nodes have no cues: the flag changes nothing for them.
    kitchen = [mapping.EgoMapper("kitchen", W, H, cues=c).update(seg, depth, (0.0, 0.0, 0.0)) for c in (0, 1)]
    np.testing.assert_array_equal(*kitchen)


def test_semantic_channels_mark_each_room_types_objects_whatever_the_target():
    seg, depth = wall_frame(2.0)
    seg[:, : W // 2] = rooms.seg_class_index("table")  # the dining room's, the living room's and the office's
    seg[:, W // 2:] = rooms.seg_class_index("sofa")  # the living room's only
    plain = mapping.EgoMapper("bedroom", W, H).update(seg, depth, (0.0, 0.0, 0.0))
    semantic = mapping.EgoMapper("bedroom", W, H, semantic=True).update(seg, depth, (0.0, 0.0, 0.0))
    assert plain.shape[0] == mapping.num_channels(False) == len(mapping.CHANNELS)
    assert semantic.shape[0] == mapping.num_channels(True) == len(mapping.CHANNELS) + len(mapping.SEMANTIC)
    np.testing.assert_array_equal(semantic[:len(mapping.CHANNELS)], plain)  # the first channels are unchanged
    marked = {node: semantic[len(mapping.CHANNELS) + k] for k, node in enumerate(mapping.SEMANTIC)}
    # The sofa (right half of the frame) lands right of the agent, the table left: columns beyond / before the middle.
    left, right = (slice(None), slice(None, mapping.WINDOW // 2)), (slice(None), slice(mapping.WINDOW // 2, None))
    assert marked["living_room"][left].any() and marked["living_room"][right].any()
    for node in ("dining_room", "office"):
        assert marked[node][left].any() and not marked[node][right].any()
    for node in ("kitchen", "bathroom", "bedroom", "garage"):
        assert not marked[node].any()
