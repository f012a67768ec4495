"""Tests for the room classifier: the bit filter, panoramas, the env wrapper, and the tiny trainer."""

import dataclasses

import numpy as np
import pytest
import torch

import leaps_mj
from leaps_mj.environment import episodes
from leaps_mj.learning import classifier, nets, train_classifier
from leaps_mj.planning import agents
from leaps_mj.world import rooms

KITCHEN = rooms.room_index("kitchen")


def test_bit_filter_needs_three_consecutive_confident_steps():
    f = classifier.BitFilter()
    p = np.zeros(rooms.NUM_ROOM_TYPES)
    seen = []
    for value in (0.9, 0.86, 0.95, 0.99, 0.849, 0.85, 0.85, 0.85, 0.2):
        p[KITCHEN] = value
        seen.append(int(f.update(p)[KITCHEN]))
    assert seen == [0, 0, 1, 1, 0, 0, 0, 1, 0]
    f.reset()
    p[KITCHEN] = 1.0
    assert f.update(p).sum() == 0 and f.update(p).sum() == 0 and f.update(p).tolist() == np.eye(8)[KITCHEN].tolist()


def test_bit_filter_rejects_bad_input():
    with pytest.raises(ValueError, match="threshold"):
        classifier.BitFilter(threshold=1.5)
    with pytest.raises(ValueError, match="steps"):
        classifier.BitFilter(steps=0)
    with pytest.raises(ValueError, match="shape"):
        classifier.BitFilter().update(np.zeros(3))


def test_resample_keeps_the_pixel_centres_of_the_lower_resolution():
    frames = np.arange(90 * 120).reshape(90, 120)
    small = classifier.resample(frames, 40, 30)
    assert small.shape == (30, 40)
    np.testing.assert_array_equal(small, frames[1::3, 1::3])
    assert classifier.resample(frames, 120, 90) is frames


@pytest.fixture(scope="module")
def spec(tiny_dataset):
    return episodes.load_split(str(tiny_dataset), "test")[0]


def make_env(tiny_dataset):
    return leaps_mj.load(str(tiny_dataset), "test", width=40, height=30, reward="sparse", horizon=50)


def test_panorama_gives_four_distinct_views_and_leaves_the_episode_alone(tiny_dataset, spec):
    env, twin = make_env(tiny_dataset), make_env(tiny_dataset)
    try:
        ts = env.reset_to(spec)
        twin.reset_to(spec)
        pose = env.physics.agent_pose()
        seg, depth = classifier.panorama(env)
        assert seg.shape == depth.shape == (4, 30, 40) and seg.dtype == np.uint8 and depth.dtype == np.float32
        np.testing.assert_array_equal(env.physics.agent_pose(), pose)
        np.testing.assert_array_equal(seg[0], ts.observation["segmentation"])
        np.testing.assert_allclose(depth[0], ts.observation["depth"], rtol=1e-6)
        views = [(seg[i].tobytes(), depth[i].tobytes()) for i in range(4)]
        assert len(set(views)) == 4
        for action in (0, 3, 0, 4):  # the panorama changed nothing the next steps see
            a, b = env.step(action), twin.step(action)
            for key in a.observation:
                np.testing.assert_array_equal(a.observation[key], b.observation[key])
    finally:
        env.close()
        twin.close()


class FakeClassifier:
    """Kitchen at probability 0.9 from step 2 on; remembers what it was shown."""

    width, height = 20, 15

    def __init__(self):
        self.calls = []

    def probabilities(self, pano, frames):
        self.calls.append((pano, frames))
        p = np.full(rooms.NUM_ROOM_TYPES, 0.1)
        if len(self.calls) >= 2:
            p[KITCHEN] = 0.9
        return p


def test_classifier_bits_replaces_only_the_semantic_bits(tiny_dataset, spec):
    env, plain = make_env(tiny_dataset), make_env(tiny_dataset)
    fake = FakeClassifier()
    wrapped = classifier.ClassifierBits(env, fake)
    try:
        kitchen = []
        for ts, ref in ((wrapped.reset_to(spec), plain.reset_to(spec)),
                        *((wrapped.step(a), plain.step(a)) for a in (0, 3, 1, 8))):
            assert list(ts.observation) == list(ref.observation)
            for key in ref.observation:
                if key != "semantic":
                    np.testing.assert_array_equal(ts.observation[key], ref.observation[key])
            assert ts.observation["semantic"].dtype == np.uint8
            kitchen.append(int(ts.observation["semantic"][KITCHEN]))
            assert ts.observation["semantic"].sum() == kitchen[-1]
            assert (ts.step_type, ts.reward) == (ref.step_type, ref.reward)
        assert kitchen == [0, 0, 0, 1, 1]  # confident from the 2nd step, on at the 4th
        pano, frames = fake.calls[0]
        assert pano[0].shape == frames[0].shape == (4, 30, 40)  # the model resamples to its 20x15
        assert all(np.array_equal(frames[0][0], frames[0][i]) for i in range(4))  # first frame repeated
        last = fake.calls[-1][1][0][-1]
        np.testing.assert_array_equal(last, ts.observation["segmentation"])
        assert wrapped.task is env.task and wrapped.config.width == 40  # the rest is the wrapped env's
        wrapped.reset_to(spec)
        assert wrapped.filter.streak.max() <= 1 and len(set(f.tobytes() for f in fake.calls[-1][1][0])) == 1
    finally:
        wrapped.close()
        plain.close()


@pytest.mark.parametrize("truth", ["and", "or"])
def test_classifier_bits_combined_with_the_truth(tiny_dataset, spec, truth):
    env, alone = make_env(tiny_dataset), make_env(tiny_dataset)
    combined, plain = classifier.ClassifierBits(env, FakeClassifier(), truth=truth), classifier.ClassifierBits(
        alone, FakeClassifier())
    try:
        for ts, ref in ((combined.reset_to(spec), plain.reset_to(spec)),
                        *((combined.step(a), plain.step(a)) for a in (0, 3, 1, 8, 0))):
            cnn, gt = ref.observation["semantic"], np.asarray(env.task.bits, np.uint8)
            np.testing.assert_array_equal(ts.observation["semantic"], cnn & gt if truth == "and" else cnn | gt)
        with pytest.raises(ValueError, match="truth 'xor'"):
            classifier.ClassifierBits(env, FakeClassifier(), truth="xor")
    finally:
        combined.close()
        plain.close()


def test_classifier_bits_needs_pixels(tiny_dataset):
    env = leaps_mj.load(str(tiny_dataset), "test", width=40, height=30, pixels=False)
    try:
        with pytest.raises(ValueError, match="pixels"):
            classifier.ClassifierBits(env, FakeClassifier())
    finally:
        env.close()


def test_outdoor_comes_from_the_last_frames_and_the_rest_from_the_panorama():
    torch.manual_seed(0)
    net = nets.RoomClassifier(nets.RoomClassifierConfig(width=16, height=12, channels=(4, 8), strides=(1, 2)))
    model = classifier.RoomTypeClassifier(net)
    rng = np.random.default_rng(0)
    pano = (rng.integers(0, rooms.NUM_SEG_CLASSES, (4, 24, 32)).astype(np.uint8), rng.uniform(0, 5, (4, 24, 32)))
    frames = (rng.integers(0, rooms.NUM_SEG_CLASSES, (4, 24, 32)).astype(np.uint8), rng.uniform(0, 5, (4, 24, 32)))
    p = model.probabilities(pano, frames)
    on_pano = 1 / (1 + np.exp(-model.logits(pano[0][None], pano[1][None])[0]))
    on_frames = 1 / (1 + np.exp(-model.logits(frames[0][None], frames[1][None])[0]))
    assert p.shape == (rooms.NUM_ROOM_TYPES,)
    np.testing.assert_allclose(np.delete(p, classifier.OUTDOOR), np.delete(on_pano, classifier.OUTDOOR), rtol=1e-5)
    np.testing.assert_allclose(p[classifier.OUTDOOR], on_frames[classifier.OUTDOOR], rtol=1e-5)
    with pytest.raises(ValueError, match="RoomClassifier"):
        classifier.RoomTypeClassifier(nets.ControllerNet())


def test_loss_mask_and_positive_weights():
    query = np.array([classifier.OUTDOOR, KITCHEN])
    mask = train_classifier.loss_mask(query)
    assert mask[0].tolist() == np.eye(8)[classifier.OUTDOOR].tolist()
    assert mask[1].sum() == 7 and mask[1, classifier.OUTDOOR] == 0
    bits = np.zeros((4, 8))
    bits[0, KITCHEN] = 1
    w = train_classifier.pos_weight(bits, np.ones((4, 8)))
    assert w[KITCHEN] == 3.0 and w[0] == 1.0


def test_tiny_trainer_saves_resumes_and_refuses_another_config(tiny_dataset, tmp_path):
    config = dataclasses.replace(train_classifier.PRESETS["tiny"], dataset=str(tiny_dataset))
    first = train_classifier.Trainer(config, tmp_path, progress=False)
    first.train(stop_after=1)
    assert first.iteration == 1 and not first.finished
    data_time = (tmp_path / "data_train.npz").stat().st_mtime_ns
    second = train_classifier.Trainer(config, tmp_path, progress=False)
    assert second.epoch == 1 and len(second.history) == 1
    best = second.train()
    assert second.finished and [r["epoch"] for r in second.history] == [1, 2]
    assert (tmp_path / "data_train.npz").stat().st_mtime_ns == data_time
    assert set(best["types"]) <= set(rooms.ROOM_TYPES) and 0.0 <= best["accuracy"] <= 1.0
    data = second.data("train")
    assert set(data["query"].tolist()) == set(range(8)) or len(best["types"]) < 8
    assert np.all(data["bits"][np.arange(len(data["query"])), data["query"]] == data["positive"])
    model = classifier.RoomTypeClassifier.load(tmp_path / "classifier.pt")
    assert (model.width, model.height) == (config.width, config.height)
    with pytest.raises(ValueError, match="another configuration"):
        train_classifier.Trainer(dataclasses.replace(config, lr=0.5), tmp_path, progress=False)
    with pytest.raises(ValueError, match="no classifier checkpoint"):
        classifier.RoomTypeClassifier.load(tmp_path / "missing.pt")


def test_bit_agreement_counts_against_the_ground_truth(tiny_dataset, spec):
    env = classifier.ClassifierBits(make_env(tiny_dataset), FakeClassifier())
    try:
        score = classifier.BitAgreement()
        result = episodes.run_episode(env, agents.RandomAgent(0), spec, 6, observer=score)
        summary = score.summary()
        assert summary["steps"] == result["steps"] == 6
        truth_on = score.tp + score.fn
        kitchen = rooms.room_index("kitchen")
        assert score.tp[kitchen] + score.fp[kitchen] == 4  # the fake's kitchen bit is on from step 3 of 7
        assert np.all(score.fp[np.arange(8) != kitchen] == 0) and np.all(score.tp[np.arange(8) != kitchen] == 0)
        assert summary["types"]["kitchen"]["truth_steps"] == truth_on[kitchen]
        assert 0.0 <= summary["exact"] <= 1.0
    finally:
        env.close()
