"""RoomNav environment: dm_env conformance, determinism, success test, bad input."""

import json
import math
import unittest

import dm_env
import numpy as np
import pytest
from dm_env import test_utils

import leaps_mj
from leaps_mj.environment import episodes, expert
from leaps_mj.environment import roomnav as envlib
from leaps_mj.world import rooms


@pytest.fixture(scope="module")
def env(tiny_dataset):
    e = leaps_mj.load(str(tiny_dataset), "train", seed=0, horizon=200, width=64, height=48)
    yield e
    e.close()


class TestConformance(test_utils.EnvironmentTestMixin, unittest.TestCase):
    """dm_env's conformance suite, with episodes that really end (horizon 15)."""

    @pytest.fixture(autouse=True)
    def _dataset(self, tiny_dataset):
        self.dataset = tiny_dataset

    def make_object_under_test(self):
        return leaps_mj.load(str(self.dataset), "train", seed=1, horizon=15, width=32, height=24)

    def make_action_sequence(self):
        rng = np.random.default_rng(0)
        for _ in range(60):
            yield np.int32(rng.integers(rooms.NUM_ACTIONS))

    def tearDown(self):
        self.environment.close()


def test_observations_match_spec(env):
    ts = env.reset()
    assert ts.first() and ts.reward is None and ts.discount is None
    spec = env.observation_spec()
    assert set(ts.observation) == set(spec)
    for k, s in spec.items():
        s.validate(ts.observation[k])
    assert ts.observation["target"].sum() == 1
    assert ts.observation["segmentation"].max() > 0
    assert np.all(ts.observation["depth"] > 0)


def test_start_is_outside_the_target_room(env):
    for _ in range(10):
        ts = env.reset()
        t = rooms.room_index(env.episode.target)
        assert not ts.observation["semantic"][t]
        assert env.episode.geodesic > 0 and env.episode.plan_length >= 1


def test_starts_can_be_bounded_in_doors_from_the_target(tiny_dataset):
    e = leaps_mj.load(str(tiny_dataset), "train", seed=4, width=16, height=12, max_start_doors=1)
    try:
        specs = [e.sample_episode() for _ in range(40)]
        assert {s.plan_length for s in specs} == {1}
    finally:
        e.close()
    for bad in (0, 1.5, True):
        with pytest.raises(ValueError, match="max_start_doors"):
            envlib.EnvConfig(max_start_doors=bad)


def test_same_seed_same_trajectory(tiny_dataset):
    runs = []
    for _ in range(2):
        e = leaps_mj.load(str(tiny_dataset), "train", seed=7, horizon=40, width=32, height=24)
        rng = np.random.default_rng(3)
        obs = []
        ts = e.reset()
        for _ in range(60):
            obs.append({k: v.copy() for k, v in ts.observation.items()})
            ts = e.step(int(rng.integers(rooms.NUM_ACTIONS)))
        runs.append((e.episode, obs))
        e.close()
    assert runs[0][0] == runs[1][0]
    for a, b in zip(runs[0][1], runs[1][1]):
        for k in a:
            np.testing.assert_array_equal(a[k], b[k])


def test_observations_are_copies(env):
    ts = env.reset()
    seg = ts.observation["segmentation"]
    seg[:] = 0
    ts2 = env.step(8)  # stay: same view
    assert ts2.observation["segmentation"].max() > 0


@pytest.mark.parametrize("action", [9, -1, 2.0, np.float32(1), np.array([1, 2]), "left", None])
def test_invalid_actions_raise_and_env_stays_usable(env, action):
    env.reset()
    pose = env.physics.agent_pose()
    with pytest.raises(ValueError, match="invalid action"):
        env.step(action)
    np.testing.assert_array_equal(env.physics.agent_pose(), pose)
    assert env.step(np.int64(3)).mid()


def test_turning_and_moving(env):
    env.reset()
    x, y, yaw = env.physics.agent_pose()
    env.step(3)  # left 30°
    assert np.isclose(np.remainder(env.physics.agent_pose()[2] - yaw, 2 * np.pi), np.radians(30))
    env.step(4)
    env.step(8)
    np.testing.assert_allclose(env.physics.agent_pose(), (x, y, yaw), atol=1e-9)


def test_walking_into_a_wall_collides_and_stops(env):
    env.reset()
    for _ in range(80):
        ts = env.step(0)
        if ts.observation["collision"]:
            break
    assert ts.observation["collision"] == 1
    pose = env.physics.agent_pose()
    assert not env.physics.agent_in_contact(env.task.house_model.agent_geom)
    env.physics.set_agent_pose(pose)


def test_oracle_succeeds_and_success_means_seeing(tiny_dataset):
    e = leaps_mj.load(str(tiny_dataset), "test", seed=0, horizon=500, reward="sparse")
    oracle = expert.GeodesicExpert(e)
    for spec in episodes.load_split(str(tiny_dataset), "test")[::4]:
        ts = e.reset_to(spec)
        fractions = []
        while not ts.last():
            ts = e.step(oracle.act())
            fractions.append(e.task.target_fraction)
        assert ts.reward == 1.0 and ts.discount == 0.0, spec
        if spec.target != "outdoor":
            assert min(fractions[-3:]) >= 0.045
        assert e.task.in_target
    e.close()


def test_scanning_expert_turns_left_while_the_way_is_out_of_view(tiny_dataset):
    """Out of view, always left (the geodesic expert turns the shorter way); in view, the geodesic expert's action."""
    e = leaps_mj.load(str(tiny_dataset), "test", seed=0, horizon=500)
    guide, scan = expert.GeodesicExpert(e), expert.ScanningGeodesicExpert(e)
    half = expert.half_view(e)
    assert math.isclose(math.degrees(half), 37.6, abs_tol=0.1)  # fovy 60 at 4:3
    rights = 0
    for spec in episodes.load_split(str(tiny_dataset), "test")[::3]:
        e.reset_to(spec)
        x, y, _ = e.physics.agent_pose()
        field, nearest, _ = guide.field(spec.target, bool(rooms.SEE_OBJECTS.get(spec.target)))
        wp = guide.waypoint(field, nearest, np.array([x, y]))
        if wp is None:
            continue
        way = math.atan2(wp[1] - y, wp[0] - x)
        for offset in (-150, -90, -50, 50, 90, 150, -25, 25):  # heading minus the way's direction, degrees
            e.physics.set_agent_pose(np.array([x, y, way + math.radians(offset)]))
            want = guide.act()
            if abs(offset) > math.degrees(half):
                assert scan.act() == expert.LEFT, (spec, offset)
                rights += want == expert.RIGHT
            else:
                assert scan.act() == want == (expert.RIGHT if offset > 0 else expert.LEFT), (spec, offset)
    assert rights > 0, "the geodesic expert turned right somewhere the scanning one turned left"
    e.close()


def test_truncation_has_discount_one(tiny_dataset):
    e = leaps_mj.load(str(tiny_dataset), "train", seed=0, horizon=5, width=32, height=24, reward="sparse")
    ts = e.reset()
    for _ in range(5):
        ts = e.step(8)
    assert ts.last() and ts.discount == 1.0 and ts.reward == 0.0
    assert e.step(8).first()
    e.close()


def test_shaped_reward_rewards_progress(tiny_dataset):
    e = leaps_mj.load(str(tiny_dataset), "train", seed=2, horizon=300, width=32, height=24, min_start_distance=5.0)
    oracle = expert.GeodesicExpert(e)
    closer, idle = [], []
    for _ in range(3):
        e.reset()
        for _ in range(40):
            d0, f0 = e.task.distance, e.task.target_fraction
            ts = e.step(oracle.act())
            if ts.last() or e.task.in_target:
                break
            # Remove the pixel bonus (change of target pixels) to see the rest.
            rest = ts.reward - (min(e.task.target_fraction / 0.1, 1) - min(f0 / 0.1, 1))
            if d0 - e.task.distance > 0.3:
                closer.append(rest)
            elif d0 == e.task.distance and not ts.observation["collision"]:
                idle.append(rest)
    assert closer and idle
    np.testing.assert_allclose(closer, np.clip(closer, 0.3, 0.5))  # progress, clipped at 0.5
    np.testing.assert_allclose(idle, -0.1)  # turning in place costs time, nothing else
    e.close()


def test_reset_to_runs_the_given_episode(env):
    spec = env.sample_episode()
    ts = env.reset_to(spec.to_json())
    assert env.episode == spec
    np.testing.assert_allclose(ts.observation["pose"], spec.start, atol=1e-5)
    target = np.zeros(8, np.uint8)
    target[rooms.room_index(spec.target)] = 1
    np.testing.assert_array_equal(ts.observation["target"], target)


def test_fixed_episodes(tiny_dataset):
    eps = episodes.load_split(str(tiny_dataset), "test")
    models = {hm.house.id: hm for hm in episodes.house_models(str(tiny_dataset), "test")}
    assert {e.plan_length for e in eps} >= {1, 2}
    for e in eps:
        hm = models[e.house]
        assert not hm.semantic_bits(*e.start[:2])[rooms.room_index(e.target)]
        assert hm.plan_length(hm.room_at(e.start[:2]), e.target) == e.plan_length
        assert 0 < e.geodesic < 1e3


@pytest.mark.parametrize("kwargs, message", [
    (dict(split="bogus"), "unknown split"),
    (dict(dataset="no-such-dataset"), "no house dataset"),
    (dict(targets=("attic",)), "unknown target room type"),
    (dict(width=2), "resolution"),
    (dict(reward="dense"), "reward"),
    (dict(horizon=0), "horizon"),
    (dict(colour=True), "unknown config keys"),
])
def test_bad_configuration(tiny_dataset, kwargs, message):
    kwargs.setdefault("dataset", str(tiny_dataset))
    with pytest.raises(ValueError, match=message):
        leaps_mj.load(**kwargs)


def test_bad_episode_specs(env):
    spec = env.sample_episode().to_json()
    with pytest.raises(ValueError, match="unknown house"):
        env.reset_to({**spec, "house": "train_9999"})
    with pytest.raises(ValueError, match="unknown room type"):
        env.reset_to({**spec, "target": "attic"})
    with pytest.raises(ValueError, match="not an episode spec"):
        env.reset_to({"house": "x"})
    assert env.step(0) is not None  # still usable


def test_missing_and_corrupt_house_files(tiny_dataset, tmp_path):
    src = sorted((tiny_dataset / "train").glob("*.json"))[0]
    (tmp_path / src.name).write_text(src.read_text())
    (tmp_path / src.with_suffix(".xml").name).write_text("<mujoco><worldbody><geom type='box'")
    with pytest.raises(ValueError, match="does not compile"):
        leaps_mj.load(houses_dir=str(tmp_path))
    (tmp_path / src.name).write_text("{not json")
    with pytest.raises(ValueError, match="not valid JSON"):
        leaps_mj.load(houses_dir=str(tmp_path))
    (tmp_path / src.with_suffix(".xml").name).unlink()
    (tmp_path / src.name).write_text(json.dumps({"format_version": 1}))
    with pytest.raises(ValueError, match="not a valid leaps_mj house"):
        leaps_mj.load(houses_dir=str(tmp_path))


def test_episode_file_errors(tmp_path):
    bad = tmp_path / "eps.jsonl"
    bad.write_text('{"house": "a", "start": [0, 0], "target": "kitchen"}\n')
    with pytest.raises(ValueError, match="eps.jsonl:1"):
        envlib.load_episodes(bad)
    with pytest.raises(ValueError, match="does not exist"):
        envlib.load_episodes(tmp_path / "missing.jsonl")


def test_blind_mode_keeps_semantics(tiny_dataset):
    e = leaps_mj.load(str(tiny_dataset), "train", seed=0, pixels=False, width=32, height=24)
    ts = e.reset()
    assert ts.observation["segmentation"].max() == 0
    assert ts.observation["semantic"].sum() + (e.task.house_model.room_at(ts.observation["pose"][:2]) >= 0) >= 1
    e.close()


def test_step_type_sequence_across_episodes(env):
    ts = env.reset()
    kinds = [ts.step_type]
    for _ in range(450):
        ts = env.step(0 if len(kinds) % 3 else 3)
        kinds.append(ts.step_type)
    assert kinds.count(dm_env.StepType.FIRST) >= 2  # horizon 200 truncates


def test_switching_houses_renders_each_house_correctly(tiny_dataset):
    """Renderers of several houses share a GL context; each must draw its own."""
    e = leaps_mj.load(str(tiny_dataset), "train", seed=0, width=32, height=24)
    specs = [e.sample_episode() for _ in range(6)]
    assert len({s.house for s in specs}) > 1
    seen = [e.reset_to(s).observation for s in specs]
    e.close()
    for spec, obs in zip(specs, seen):
        fresh = leaps_mj.load(str(tiny_dataset), "train", seed=0, width=32, height=24)
        ref = fresh.reset_to(spec).observation
        fresh.close()
        np.testing.assert_array_equal(obs["segmentation"], ref["segmentation"])
        np.testing.assert_allclose(obs["depth"], ref["depth"])


def test_indoor_target_means_untyped_space(tiny_dataset):
    """``indoor`` (hallways) can be a target, for the sub-policy of hallway hops."""
    e = leaps_mj.load(str(tiny_dataset), "train", seed=3, width=32, height=24, horizon=300,
                      targets=("indoor",), reward="sparse")
    oracle = expert.GeodesicExpert(e)
    for _ in range(3):
        ts = e.reset()
        assert e.episode.target == "indoor" and ts.observation["target"].sum() == 0
        while not ts.last():
            ts = e.step(oracle.act())
        assert ts.reward == 1.0 and not ts.observation["semantic"].any()
    e.close()
