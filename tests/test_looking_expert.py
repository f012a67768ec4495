"""Tests of the looking expert: it turns left until the target is seen or the room looked around,
then acts as the geodesic expert; memory per episode; its use as a DAgger teacher; and the hop success
of the teachers that act on what was observed (looking, observable)."""

import dataclasses
import math

import numpy as np
import pytest

from leaps_mj.environment import episodes, expert, roomnav
from leaps_mj.environment.looking_expert import LookingGeodesicExpert
from leaps_mj.evaluation import registry
from leaps_mj.learning import policy_config, train_policy, training_env
from leaps_mj.world import rooms


@pytest.fixture(scope="module")
def env(tiny_dataset):
    e = roomnav.load(str(tiny_dataset), "test", reward="sparse", horizon=100)
    yield e
    e.close()


def _unseen_start(env, hop_episodes):
    """A hop start towards a room type with see-objects, none of them in view in the first frame."""
    for spec in hop_episodes:
        if rooms.SEE_OBJECTS.get(spec.target):
            env.reset_to(spec)
            if env.task.target_fraction == 0:
                return spec
    raise AssertionError("no start with the target out of view")


def test_it_turns_left_until_the_target_is_seen_or_the_room_looked_around(env, hop_episodes):
    spec = _unseen_start(env, hop_episodes)
    env.reset_to(spec)
    looker, guide = LookingGeodesicExpert(env, seed=0), expert.GeodesicExpert(env, seed=0)
    turns, in_view = 0, []
    for _ in range(40):
        in_view.append(env.task.target_fraction > 0)
        action = looker.act()
        if looker.seen or looker.looked_around():
            break
        assert action == expert.LEFT and not env.task.in_target
        turns += 1
        env.step(action)
    # A full circle takes at most 12 turns of 30 degrees (fewer once the camera's width is counted).
    assert 0 < turns <= 12
    assert looker.seen == any(in_view)
    # From here on it acts as the geodesic expert (same unsticking draws: a twin with the same seed).
    assert action == guide.act() or env.task.collision


def test_coverage_counts_the_camera_width(env, hop_episodes):
    spec = _unseen_start(env, hop_episodes)
    env.reset_to(spec)
    looker = LookingGeodesicExpert(env)
    looker.observe()
    covered = looker.covered[looker.room]
    half = math.degrees(expert.half_view(env))
    # One frame covers the bins whose centres lie within the half view of the heading: about 75 of 360 degrees.
    assert abs(covered.sum() * 10 - 2 * half) <= 10
    assert not looker.looked_around()


def test_memory_is_per_episode(env, hop_episodes):
    spec = _unseen_start(env, hop_episodes)
    env.reset_to(spec)
    looker = LookingGeodesicExpert(env)
    for _ in range(5):
        env.step(looker.act())
    assert looker.covered[looker.room].sum() > 8
    env.reset_to(spec)
    looker.observe()
    assert looker.covered[looker.room].sum() <= 8 and not looker.seen


def test_targets_without_see_objects_get_the_geodesic_experts_actions(env, hop_episodes):
    spec = next(s for s in hop_episodes if not rooms.SEE_OBJECTS.get(s.target))
    runs = []
    for teacher_class in (LookingGeodesicExpert, expert.GeodesicExpert):
        env.reset_to(spec)
        teacher, actions = teacher_class(env, seed=2), []
        for _ in range(30):
            actions.append(teacher.act())
            if env.step(actions[-1]).last():
                break
        runs.append(actions)
    assert runs[0] == runs[1]


@pytest.mark.parametrize("name", ["oracle-look", "observable"])
def test_the_teachers_reach_the_target_from_most_hop_starts(env, hop_episodes, name):
    """The looking and the observable teachers, as agents (the observable one, measured on these 32 episodes:
    all 1-door starts within 49 steps, all 2-door ones within 80)."""
    steps = {1: [], 2: []}
    for k, spec in enumerate(hop_episodes):
        result = episodes.run_episode(env, registry.make_agent(name, env, seed=k), spec, 100)
        steps[spec.plan_length].append(result["success_step"])
    one, two = steps[1], steps[2]
    assert len(one) >= 12 and len(two) >= 12
    assert sum(s is not None and s <= 60 for s in one) >= len(one) - 2
    assert sum(s is not None for s in two) >= len(two) - 3


def test_it_serves_as_the_dagger_teacher(tiny_dataset):
    assert policy_config.TEACHERS["geodesic-look"] is LookingGeodesicExpert
    config = dataclasses.replace(train_policy.PRESETS["tiny"], dataset=str(tiny_dataset), teacher="geodesic-look",
                                 method="dagger")
    worker = training_env.make_training_env(0, config, 0, True, dataset=str(tiny_dataset), split="train",
                                            width=config.width, height=config.height)
    twin = LookingGeodesicExpert(worker._env, seed=0)
    assert type(worker._expert) is LookingGeodesicExpert
    ts, labels = worker.reset(), []
    for _ in range(30):
        labels.append(int(ts.observation["expert_action"]))
        assert labels[-1] == twin.act()
        ts = worker.step(labels[-1])
        if ts.last():
            ts = worker.reset()
    worker.close()
    assert np.isin(labels, np.arange(rooms.NUM_ACTIONS)).all()
