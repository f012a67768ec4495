"""Tests of the observable expert: per-episode memory, revealed rooms, the geodesic finish, the
room-id table and its use as the sub-policy trainer's teacher (its hop success: test_looking_expert.py)."""

import dataclasses

import numpy as np
import pytest

from leaps_mj.environment import roomnav
from leaps_mj.environment.expert import GeodesicExpert
from leaps_mj.environment.observable_expert import REVEAL_FRACTION, ObservableExpert
from leaps_mj.learning import policy_config, train_policy, training_env
from leaps_mj.world import rooms


@pytest.fixture(scope="module")
def env(tiny_dataset):
    e = roomnav.load(str(tiny_dataset), "test", reward="sparse", horizon=100)
    yield e
    e.close()


def _room_fractions(env) -> np.ndarray:
    """Share of the current frame showing each room of the house (by room id)."""
    ids = env.segment_luts[3].take(env.task.segments).ravel() + 1
    return np.bincount(ids, minlength=len(env.task.house_model.house.rooms) + 1)[1:] / ids.size


def test_room_lut_labels_room_geoms_with_their_room_id(env, hop_episodes):
    env.reset_to(hop_episodes[0])
    hm, model = env.task.house_model, env.physics.model
    for g in range(model.ngeom):
        parts = model.id2name(g, "geom").split("__")
        expected = int(parts[2][1:]) if len(parts) >= 3 and parts[2].startswith("r") else -1
        assert hm.room_lut[g + 1] == expected, model.id2name(g, "geom")
        if parts[0] == "floor" and expected >= 0:
            assert hm.house.rooms[expected].type == parts[1]
    assert hm.room_lut[0] == -1


def test_revealed_rooms_grow_and_follow_the_frames(env, hop_episodes):
    spec = next(s for s in hop_episodes if s.plan_length == 2)
    env.reset_to(spec)
    teacher = ObservableExpert(env, seed=1)
    history = []
    for _ in range(40):
        before = set(teacher.revealed) if history else set()
        action = teacher.act()
        fractions = _room_fractions(env)
        room = env.task.house_model.room_at(env.physics.agent_pose()[:2])
        assert room in teacher.visited and teacher.visited <= teacher.revealed
        assert before <= teacher.revealed
        # Newly revealed rooms: the one stood in, or at least REVEAL_FRACTION of this frame.
        for r in teacher.revealed - before:
            assert r == room or fractions[r] >= REVEAL_FRACTION
        history.append(set(teacher.revealed))
        if env.step(action).last():
            break
    assert len(history[-1]) > len(history[0]), "walking on reveals more rooms"
    assert len(teacher.visited) > 1, "the exploration walk passed a door"


def test_furniture_reveals_only_rooms_whose_furniture_is_in_the_frame(env, hop_episodes):
    with pytest.raises(ValueError, match="reveal 'floor'"):
        ObservableExpert(env, reveal="floor")
    spec = next(s for s in hop_episodes if s.plan_length == 2)
    env.reset_to(spec)
    by_room, by_furniture = ObservableExpert(env, seed=1), ObservableExpert(env, seed=1, reveal="furniture")
    furniture = np.isin(env.segment_luts[0], [rooms.seg_class_index(c) for c in rooms.FURNITURE_CLASSES])
    fewer = False
    for _ in range(40):
        before = set(by_furniture.revealed)
        action = by_room.act()
        by_furniture.observe()
        ids = np.where(furniture.take(env.task.segments), env.segment_luts[3].take(env.task.segments), -1).ravel() + 1
        shares = np.bincount(ids, minlength=len(env.task.house_model.house.rooms) + 1)[1:] / ids.size
        assert by_furniture.revealed <= by_room.revealed and by_furniture.visited == by_room.visited
        for r in by_furniture.revealed - before - by_furniture.visited:  # newly revealed by this frame's furniture
            assert shares[r] >= REVEAL_FRACTION
        fewer |= by_furniture.revealed < by_room.revealed
        if env.step(action).last():
            break
    assert fewer, "a room seen by its floor or walls alone is not revealed by furniture"


def test_memory_is_per_episode(env, hop_episodes):
    spec, other = hop_episodes[0], next(s for s in hop_episodes if s.house != hop_episodes[0].house)
    env.reset_to(spec)
    teacher = ObservableExpert(env, seed=0)
    action = teacher.act()
    start = (set(teacher.visited), set(teacher.revealed), teacher.goal)
    for _ in range(25):
        ts = env.step(action)
        if ts.last():
            break
        action = teacher.act()
    assert (set(teacher.visited), set(teacher.revealed)) != start[:2]
    # The same spec again (same object: the step counter tells), then an episode in another house.
    env.reset_to(spec)
    teacher.act()
    assert (set(teacher.visited), set(teacher.revealed), teacher.goal) == start and not teacher.passed
    env.reset_to(other)
    teacher.act()
    hm = env.task.house_model
    assert teacher.visited == {hm.room_at(other.start[:2])}
    assert teacher.revealed <= set(range(len(hm.house.rooms)))


def test_with_the_target_in_view_from_the_start_it_acts_as_the_geodesic_expert(env, hop_episodes):
    # A start outside the target's only room but looking into it: where the geodesic expert,
    # walking from a hop start, first reveals that room.
    start = None
    for spec in hop_episodes:
        env.reset_to(spec)
        hm = env.task.house_model
        goal = [r.id for r in hm.house.rooms if r.type == spec.target]
        if len(goal) != 1:
            continue
        watcher, guide = ObservableExpert(env), GeodesicExpert(env)
        for _ in range(40):
            watcher.observe()
            pose = env.physics.agent_pose()
            if goal[0] in watcher.revealed and hm.room_at(pose[:2]) != goal[0]:
                start = roomnav.EpisodeSpec(spec.house, tuple(float(v) for v in pose), spec.target)
                break
            if env.step(guide.act()).last():
                break
        if start is not None:
            break
    assert start is not None
    runs = []
    for teacher_class in (ObservableExpert, GeodesicExpert):
        env.reset_to(start)
        teacher, actions = teacher_class(env, seed=3), []
        if isinstance(teacher, ObservableExpert):
            teacher.observe()
            assert goal[0] in teacher.revealed
        for _ in range(40):
            actions.append(teacher.act())
            if env.step(actions[-1]).last():
                break
        runs.append((actions, env.task.success))
    assert runs[0] == runs[1] and runs[0][1]


def test_the_teacher_option_is_validated_and_defaults_to_the_geodesic_expert():
    assert train_policy.PRESETS["tiny"].teacher == "geodesic"
    assert policy_config.TEACHERS["geodesic"] is GeodesicExpert
    with pytest.raises(ValueError, match="teacher 'oracle'"):
        dataclasses.replace(train_policy.PRESETS["tiny"], teacher="oracle")
    args = train_policy.build_parser().parse_args(["--teacher", "observable"])
    assert args.teacher == "observable"


def test_a_tiny_training_run_with_the_observable_teacher(tiny_dataset, tmp_path):
    config = dataclasses.replace(train_policy.PRESETS["tiny"], dataset=str(tiny_dataset), teacher="observable",
                                 method="dagger", total_steps=2 * 16)
    # In one process: the worker's environment labels with the observable expert.
    worker = training_env.make_training_env(0, config, 0, True, dataset=str(tiny_dataset), split="train",
                                            width=config.width, height=config.height)
    twin = ObservableExpert(worker._env, seed=0)
    assert type(worker._expert) is ObservableExpert
    ts = worker.reset()
    for _ in range(10):
        label = int(ts.observation["expert_action"])
        assert label == twin.act()
        ts = worker.step(label)
        if ts.last():
            break
    worker.close()
    trainer = train_policy.Trainer(config, "kitchen", tmp_path, progress=False)
    labels = []
    update = trainer._update
    trainer._update = lambda unroll, batch, rng: (labels.append(unroll.labels[unroll.valid > 0]),
                                                  update(unroll, batch, rng))[1]
    trainer.train()
    assert trainer.finished and len(labels) >= config.iterations
    labels = np.concatenate(labels)
    assert ((labels >= 0) & (labels < 9)).all()
