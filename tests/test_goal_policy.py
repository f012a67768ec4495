"""Tests of the map-goal sub-policy: planner, driver, teacher, network, sub-policy and trainer."""

import csv
import dataclasses
import math

import numpy as np
import pytest
import torch

import leaps_mj
from leaps_mj.environment import expert, goal_teacher, map_navigation, mapping
from leaps_mj.evaluation import registry
from leaps_mj.learning import checkpoints, credit, goal_policy, nets, train_goal
from leaps_mj.world import rooms

W, H = 24, 18


def test_path_distances_go_around_walls():
    free = np.ones((5, 5), bool)
    free[1:4, 2] = False  # a wall in column 2, open at the top and bottom rows
    dist = map_navigation.path_distances(free, (2, 0))
    assert dist[2, 0] == 0 and dist[2, 1] == 1
    assert dist[2, 2] == np.inf
    # Round the wall's top end: (2,0) -> (1,1) -> (0,2) -> (1,3) -> (2,4), 4 diagonal steps.
    assert dist[2, 4] == pytest.approx(4 * math.sqrt(2))
    closed = free.copy()
    closed[:, 2] = False
    assert np.isinf(map_navigation.path_distances(closed, (2, 0))[2, 4])


def _empty_step(driver, pose, collision=False):
    seg = np.zeros((H, W), np.uint8)  # nothing seen: no cell blocked
    return driver.observe({"segmentation": seg, "depth": np.ones((H, W), np.float32), "pose": pose,
                           "collision": np.uint8(collision)})


def test_driver_turns_towards_the_goal_then_walks_and_stops_there():
    driver = map_navigation.GoalDriver("outdoor", W, H)
    pose = np.array([0.0, 0.0, 0.0])
    _empty_step(driver, pose)
    assert driver.needs_goal()
    driver.goal = np.array([0.0, 2.0])  # 2 m to the left
    assert driver.act() == expert.LEFT
    pose = np.array([0.0, 0.0, math.pi / 2])
    _empty_step(driver, pose)
    assert driver.act() == expert.FORWARD
    _empty_step(driver, np.array([0.0, 1.9, math.pi / 2]))
    # Arrived; nothing of the target (outdoor has no see-objects) is mapped: it looks around.
    assert driver.act() == expert.LEFT


def test_driver_goes_round_what_it_mapped():
    driver = map_navigation.GoalDriver("outdoor", W, H)
    _empty_step(driver, np.array([0.0, 0.0, 0.0]))
    driver.mapper.blocked[mapping.GRID // 2 - 4:mapping.GRID // 2 + 1, mapping.GRID // 2 + 4] = True  # a wall 1 m ahead
    wp = driver.navigator.waypoint(np.array([0.0, 0.0, 0.0]), (2.0, -0.05))
    assert wp is not None and wp[1] > 0.2  # around the wall's open (left) end, not straight on
    driver.mapper.blocked[:, mapping.GRID // 2 + 4] = True  # now closed: it heads for the goal regardless
    np.testing.assert_allclose(driver.navigator.waypoint(np.array([0.0, 0.0, 0.0]), (2.0, -0.05)), (2.0, -0.05))


def test_waypoints_cut_a_corner_only_where_the_map_shows_the_shortcut_free():
    driver = map_navigation.GoalDriver("outdoor", W, H)
    pose = np.array([0.0, 0.0, 0.0])
    _empty_step(driver, pose)
    nav, m = driver.navigator, driver.mapper
    goal = (1.5, -1.5)  # ahead and to the right: open floor, the path runs straight at it
    far = nav.waypoint(pose, goal)
    assert math.hypot(*far[:2]) > 2 * mapping.CELL  # LOOKAHEAD cells down the path
    # A post right of the agent's line to that waypoint: the shortcut would graze it, so it steers
    # at a nearer cell of the path, whose straight way keeps the body off the post.
    row, col, _ = m.cells(0.45, -0.2)
    m.blocked[row, col] = True
    near = nav.waypoint(pose, goal)
    assert math.hypot(*near[:2]) < math.hypot(*far[:2])
    assert nav._clear(pose, near) and not nav._clear(pose, far)


def test_set_goal_reads_window_cells_around_the_pose():
    driver = map_navigation.GoalDriver("kitchen", W, H)
    pose = np.array([3.0, 1.0, math.pi / 2])  # facing +y
    _empty_step(driver, pose)
    driver.set_goal(0 * mapping.WINDOW + mapping.WINDOW // 2)  # top row, centre: ahead of the agent
    assert driver.goal[1] > 1.0 + 3.5 and abs(driver.goal[0] - 3.0) < 0.3
    assert driver.mapper.window_cell(pose, *driver.goal) == (0, mapping.WINDOW // 2)


@pytest.fixture(scope="module")
def env(tiny_dataset):
    e = leaps_mj.load(str(tiny_dataset), "train", seed=0, width=W, height=H, horizon=60, max_start_doors=1)
    yield e
    e.close()


@pytest.mark.parametrize("name", ["oracle-map", "oracle-map-observable", "oracle-map-furniture", "oracle-map-sensed",
                                  "oracle-map-gated", "oracle-map-potential"])
def test_teacher_goals_lie_in_the_window_and_the_oracle_map_agent_reaches_rooms(env, name):
    agent = registry.make_agent(name, env, seed=0)
    agent.width, agent.height = W, H
    successes = 0
    for episode in range(4):
        ts = env.reset()
        agent.reset(env.episode.target)
        while not ts.last():
            action = agent.step(ts)
            label = agent.teacher.cell(agent.driver.mapper, agent.driver.pose)
            assert 0 <= label < mapping.WINDOW ** 2
            ts = env.step(action)
        successes += env.task.success
    assert successes >= 2


def test_observable_goals_follow_the_exploration_walk_until_the_target_room_is_seen(env):
    agent = registry.make_agent("oracle-map-observable", env, seed=0)
    agent.width, agent.height = W, H
    geodesic = goal_teacher.TeacherGoals(env)
    walked = finished = differ = 0
    for _ in range(6):
        ts = env.reset()
        agent.reset(env.episode.target)
        while not ts.last():
            action = agent.step(ts)  # the teacher observed this step and chose its goal
            teacher, pose = agent.teacher, agent.driver.pose
            label = teacher.cell(agent.driver.mapper, pose)
            if not teacher.expert.target_revealed() and teacher.expert.goal is not None:
                walk = teacher.expert._door_field(*teacher.expert.goal)
                assert label == teacher.goal_cell(*walk, agent.driver.mapper, pose)
                walked += 1
                differ += label != geodesic.cell(agent.driver.mapper, pose)
            elif teacher.expert.target_rooms(env.episode.target) == ():
                assert label == geodesic.cell(agent.driver.mapper, pose)  # all its rooms seen: the geodesic goal
                finished += 1
            ts = env.step(action)
    assert walked and finished and differ  # exploring, it does not always head where the map leads


def test_the_sensed_teacher_explores_only_mapped_doors_and_else_looks_around(env):
    agent = registry.make_agent("oracle-map-sensed", env, seed=0)
    agent.width, agent.height = W, H
    looked = walked = 0
    for _ in range(4):
        ts = env.reset()
        agent.reset(env.episode.target)
        doors = env.task.house_model.house.doors
        while not ts.last():
            action = agent.step(ts)
            teacher, mapper = agent.teacher, agent.driver.mapper
            label = teacher.cell(mapper, agent.driver.pose)
            if not teacher.expert.target_revealed():
                if teacher.expert.goal is None:  # no mapped door left: the agent's own cell
                    assert label == (mapping.WINDOW // 2) * mapping.WINDOW + mapping.WINDOW // 2
                    looked += 1
                else:
                    assert goal_teacher.door_mapped(mapper, doors[teacher.expert.goal[0]].center)
                    walked += 1
            ts = env.step(action)
    assert looked and walked


def test_the_gated_teacher_takes_the_geodesic_door_once_mapped_and_looks_then_explores_before(env):
    agent = registry.make_agent("oracle-map", env, seed=0)  # walks the geodesic teacher's goals; the gated one labels
    agent.width, agent.height = W, H
    gated, geodesic = goal_teacher.GatedTeacherGoals(env), goal_teacher.TeacherGoals(env)
    centre = (mapping.WINDOW // 2) * mapping.WINDOW + mapping.WINDOW // 2
    kinds = set()
    for _ in range(6):
        ts = env.reset()
        agent.reset(env.episode.target)
        while not ts.last():
            action = agent.step(ts)
            mapper, pose = agent.driver.mapper, agent.driver.pose
            looked = gated._looked if gated._episode is env.task.episode else 0
            label, _ = gated.labels(mapper, pose, potential=False)
            door = gated.door_out(pose)
            if gated.memory.target_revealed() or door is None or goal_teacher.door_mapped(mapper, door.center):
                assert label == geodesic.cell(mapper, pose) and gated._looked == looked
                kinds.add("geodesic")
            elif looked < goal_teacher.GATED_LOOK:
                assert label == centre and gated._looked == looked + 1
                kinds.add("look")
            else:
                assert 0 <= label < mapping.WINDOW ** 2 and gated._looked == looked
                kinds.add("frontier")
            ts = env.step(action)
    assert {"geodesic", "look"} <= kinds


def test_the_trainer_labels_with_the_teacher_its_config_names(tiny_dataset, tmp_path):
    config = dataclasses.replace(train_goal.PRESETS["tiny"], dataset=str(tiny_dataset), teacher="observable")
    shard, = train_goal.training_env.training_houses(config.dataset, None, 0, 1, tmp_path, name="goal")
    samples = train_goal.collect(config, str(shard), seed=3, episodes=2, beta=1.0, state_dict=None)
    assert len(samples["label"]) == len(samples["maps"]) > 0 and samples["teacher"].all()
    with pytest.raises(ValueError, match="teacher 'map'"):
        train_goal.GoalTrainConfig(teacher="map")
    assert set(train_goal.TEACHERS) == {"geodesic", "observable", "observable-furniture", "sensed", "gated"}


def test_goal_net_shapes_and_errors():
    net = nets.GoalNet(nets.GoalNetConfig(width=W, height=H))
    maps = torch.zeros(3, len(mapping.CHANNELS), mapping.WINDOW, mapping.WINDOW, dtype=torch.uint8)
    assert net(maps, torch.tensor([0, 4, 8])).shape == (3, mapping.WINDOW ** 2)
    with pytest.raises(ValueError, match="egomap has shape"):
        net(maps[:, :3], torch.tensor([0, 4, 8]))
    with pytest.raises(ValueError, match=r"indices in \[0, 9\)"):
        net(maps, torch.tensor([0, 4, 9]))
    with pytest.raises(ValueError, match="multiple of"):
        nets.GoalNetConfig(window=30)


def test_goal_sub_policy_loads_acts_and_refuses_other_checkpoints(tmp_path, env):
    torch.manual_seed(0)
    config = nets.GoalNetConfig(width=W, height=H)
    checkpoints.save_checkpoint(tmp_path / goal_policy.GOAL, nets.GoalNet(config), config, {})
    policy = goal_policy.GoalSubPolicy(tmp_path)
    assert policy.targets == rooms.GRAPH_NODES
    with pytest.raises(ValueError, match="reset"):
        policy.act(env.reset())
    with pytest.raises(ValueError, match="no sub-policy for target"):
        policy.reset("attic")
    policy.reset("kitchen")
    assert policy.goal is None  # no goal chosen yet
    policy.act(env.reset())
    goal = policy.goal
    assert goal.shape == (2,) and np.all(np.isfinite(goal))
    goal += 100.0  # a copy: the driver's goal does not move
    assert np.allclose(policy.goal, goal - 100.0)
    # The map is built afresh every `memory` steps (by default its training runs' horizon); 0 never forgets.
    assert policy.memory == goal_policy.MEMORY  # a checkpoint without training metadata
    short = goal_policy.GoalSubPolicy(tmp_path, memory=3)
    short.reset("kitchen")
    ts = env.reset()
    for _ in range(3):
        ts = env.step(short.act(ts))
    assert short._driver.steps == 3 and short._driver.mapper.grid[mapping.CHANNELS.index("visited")].sum() >= 1
    ts = env.step(short.act(ts))
    assert short._driver.steps == 1  # forgotten before the 4th step, then one step taken
    fresh = goal_policy.GoalSubPolicy(tmp_path, memory=0)
    fresh.reset("kitchen")
    ts = env.reset()
    for _ in range(5):
        ts = env.step(fresh.act(ts))
    assert fresh._driver.steps == 5
    with pytest.raises(ValueError, match="memory -1: expected a non-negative"):
        goal_policy.GoalSubPolicy(tmp_path, memory=-1)

    def run():
        ts = env.reset_to(spec)
        policy.reset(spec.target)
        actions = []
        for _ in range(10):
            actions.append(policy.act(ts))
            ts = env.step(actions[-1])
        return actions

    env.reset()
    spec = env.episode
    first = run()
    assert all(0 <= a < rooms.NUM_ACTIONS for a in first) and run() == first
    pixel = nets.PolicyConfig(width=W, height=H, conv_channels=(8, 8), hidden=16, lstm=16)
    checkpoints.save_checkpoint(tmp_path / "other" / goal_policy.GOAL, nets.ActorCritic(pixel), pixel, {})
    with pytest.raises(ValueError, match="not a map-goal network"):
        goal_policy.GoalSubPolicy(tmp_path / "other")
    with pytest.raises(ValueError, match="train one with"):
        goal_policy.GoalSubPolicy(tmp_path / "missing")


def test_trainer_writes_the_network_and_a_killed_run_resumes_to_the_same_bytes(tiny_dataset, tmp_path):
    config = dataclasses.replace(train_goal.PRESETS["tiny"], dataset=str(tiny_dataset), rounds=2, episodes=2)
    whole = train_goal.GoalTrainer(config, tmp_path / "whole", progress=False)
    whole.train()
    parts = train_goal.GoalTrainer(config, tmp_path / "parts", progress=False)
    parts.train(stop_after=1)
    assert not parts.finished
    resumed = train_goal.GoalTrainer(config, tmp_path / "parts", progress=False)
    assert resumed.resume(config.width, config.height) and resumed.iteration == 1
    resumed.train()
    # A finished one-round run, extended to two rounds, is the two-round run; it cannot shrink.
    short = train_goal.GoalTrainer(dataclasses.replace(config, rounds=1), tmp_path / "extended", progress=False)
    short.train()
    assert short.finished
    extended = train_goal.GoalTrainer(config, tmp_path / "extended", progress=False)
    assert extended.resume(config.width, config.height) and not extended.finished
    extended.train()
    for other in (resumed, extended):
        for a, b in zip(whole.model.state_dict().values(), other.model.state_dict().values()):
            torch.testing.assert_close(a, b, rtol=0, atol=0)
    with pytest.raises(ValueError, match="rounds: saved 2, given 1"):
        train_goal.GoalTrainer(dataclasses.replace(config, rounds=1), tmp_path / "extended").resume()
    net, extra = goal_policy.load_goal_net(tmp_path / "whole" / goal_policy.GOAL)
    assert extra["round"] == 2 and isinstance(net, nets.GoalNet)
    data = np.load(tmp_path / "whole" / "data" / "round_001.npz")
    assert data["maps"].shape[0] == data["label"].shape[0] > 0
    with pytest.raises(ValueError, match="beta"):
        dataclasses.replace(config, beta=1.5)


def test_soft_goal_labels_and_mirroring():
    labels = torch.tensor([5 * mapping.WINDOW + 7, 0])
    sharp = torch.full((2, mapping.WINDOW ** 2), -20.0)
    sharp[0, labels[0]] = sharp[1, 0] = 20.0
    assert train_goal.goal_loss(sharp, labels, 0.0).item() < 1e-6
    # A spread label rewards spreading too: the sharp prediction pays for its neighbours' share.
    assert train_goal.goal_loss(sharp, labels, 1.0).item() > 1.0
    near = sharp.clone()
    near[0, labels[0] + 1] = 20.0  # the cell to its right as likely: closer to the spread label
    assert train_goal.goal_loss(near, labels, 1.0) < train_goal.goal_loss(sharp, labels, 1.0)
    maps = torch.arange(2 * mapping.WINDOW ** 2).reshape(2, 1, mapping.WINDOW, mapping.WINDOW)
    flipped, moved = train_goal.mirror(maps, labels, torch.tensor([True, False]))
    assert moved.tolist() == [5 * mapping.WINDOW + mapping.WINDOW - 1 - 7, 0]
    assert torch.equal(flipped[0, 0, 3], maps[0, 0, 3].flip(0)) and torch.equal(flipped[1], maps[1])
    twice, back = train_goal.mirror(flipped, moved, torch.tensor([True, False]))
    assert torch.equal(twice, maps) and torch.equal(back, labels)


def test_quarter_turns_move_the_goal_with_the_map():
    size = mapping.WINDOW
    labels = torch.tensor([2 * size + 5] * 4)
    maps = torch.zeros(4, 2, size, size)
    maps[:, 1, 2, 5] = 1.0  # the goal's cell marked in one channel
    turned, moved = train_goal.rotate(maps, labels, torch.tensor([0, 1, 2, 3]))
    for i in range(4):
        row, col = divmod(int(moved[i]), size)
        assert turned[i, 1, row, col] == 1.0 and turned[i, 1].sum() == 1.0
    assert moved[0] == labels[0] and len(set(moved.tolist())) == 4
    back, again = train_goal.rotate(*train_goal.rotate(maps, labels, torch.tensor([1, 1, 1, 1])), torch.tensor([3] * 4))
    assert torch.equal(back, maps) and torch.equal(again, labels)


def test_the_shipped_map_goal_network_its_mu_s_and_controller_load_and_act_at_120x90(tiny_dataset, monkeypatch,
                                                                                       tmp_path):
    from leaps_mj.learning import baselines, policy_folder

    policy = goal_policy.load_default()
    mu_s = policy_folder.load_augmented(goal_policy.DEFAULT_DIR)
    assert not policy.net.config.room_bits and mu_s.net.config.room_bits
    path = policy_folder.controller_path(goal_policy.DEFAULT_DIR)
    assert path != baselines.DEFAULT_CONTROLLER
    controller = baselines.ControllerAgent.from_checkpoint(policy, path)
    env = leaps_mj.load(str(tiny_dataset), "train", seed=0, width=120, height=90, horizon=8)
    try:
        cpu = train_goal.PRESETS["cpu"]  # μ_s is the cpu preset's (session 22); the shipped network continues a
        assert mu_s.metadata["round"] == cpu.rounds  # cpu-preset network on a cpu-preset run's dataset (session 27)
        assert policy.metadata["train_config"]["init_data"] and policy.metadata["train_config"]["seed"] == 1
        for shipped in (policy, mu_s):
            assert shipped.net.config == dataclasses.replace(cpu, room_bits=shipped.net.config.room_bits).net_config
            assert (shipped.width, shipped.height) == (40, 30)
            ts = env.reset()
            shipped.reset(env.episode.target)
            while not ts.last():
                ts = env.step(shipped.act(ts))
        ts = env.reset()
        controller.reset(env.episode.target)
        while not ts.last():
            ts = env.step(controller.step(ts))
        assert controller.decisions  # it chose a sub-target
    finally:
        env.close()
    monkeypatch.setattr(goal_policy, "DEFAULT_DIR", tmp_path)
    with pytest.raises(ValueError, match="python -m leaps_mj.train goal"):
        goal_policy.load_default()


def test_a_committed_driver_finishes_its_turn_before_choosing_again():
    committed = map_navigation.GoalDriver("outdoor", W, H)
    every = map_navigation.GoalDriver("outdoor", W, H, commit_turns=False)
    for driver in (committed, every):
        _empty_step(driver, np.array([0.0, 0.0, 0.0]))
        driver.goal = np.array([-3.0, 0.0])  # behind: several turns to face it
        driver._since_goal = 0
        actions = []
        for _ in range(map_navigation.REPLAN):
            actions.append(driver.act())
            _empty_step(driver, np.array([0.0, 0.0, 0.0]))  # frames do not move it here: still turning
        assert set(actions) <= map_navigation.TURNS
    assert every.needs_goal() and not committed.needs_goal()
    committed._last_action = expert.FORWARD
    assert committed.needs_goal()


def test_a_committed_driver_looking_around_at_its_goal_chooses_again():
    """At the goal with nothing of the target mapped it turns to look around; those turns are not a walk's,
    so after REPLAN steps it takes a new goal (it used to turn there for the rest of the run)."""
    driver = map_navigation.GoalDriver("outdoor", W, H)
    pose = np.array([0.0, 0.0, 0.0])
    _empty_step(driver, pose)
    driver.set_goal(mapping.WINDOW // 2 * mapping.WINDOW + mapping.WINDOW // 2)  # its own cell: arrived
    for _ in range(map_navigation.REPLAN):
        assert not driver.needs_goal()
        assert driver.act() == expert.LEFT
        _empty_step(driver, pose)
    assert driver.needs_goal()


def test_a_network_reading_the_context_window_and_semantic_channels_trains_and_drives_with_them(
        tiny_dataset, tmp_path, env):
    config = dataclasses.replace(train_goal.PRESETS["tiny"], dataset=str(tiny_dataset), rounds=1, episodes=2,
                                 context=True, cues=True, semantic=True)
    train_goal.GoalTrainer(config, tmp_path, progress=False).train()
    data = np.load(tmp_path / "data" / "round_000.npz")
    channels = mapping.num_channels(True)
    assert config.net_config.input_channels == 2 * channels
    assert data["maps"].shape[1] == 2 * channels * mapping.WINDOW ** 2 // 8
    policy = goal_policy.GoalSubPolicy(tmp_path)
    assert policy.net.config.context and policy.net.config.cues and policy.net.config.semantic
    ts = env.reset()
    policy.reset("outdoor")
    assert 0 <= policy.act(ts) < rooms.NUM_ACTIONS
    driver = policy._drivers["outdoor"]
    assert driver.context and driver.mapper._channel_of[rooms.seg_class_index("fence")] == mapping.CHANNELS.index(
        "target")
    assert driver.mapper.grid.shape[0] == channels
    with pytest.raises(ValueError, match="context must be a bool"):
        nets.GoalNetConfig(context=1)


def test_max_updates_caps_the_learners_minibatches_per_round(tiny_dataset, tmp_path):
    config = dataclasses.replace(train_goal.PRESETS["tiny"], dataset=str(tiny_dataset), rounds=2, episodes=2)
    steps = {}
    for cap in (0, 1):
        trainer = train_goal.GoalTrainer(dataclasses.replace(config, max_updates=cap), tmp_path / str(cap),
                                         progress=False)
        trainer.train()
        steps[cap] = int(next(iter(trainer.optimizer.state.values()))["step"])
    assert steps[1] == 2 < steps[0]
    with pytest.raises(ValueError, match="max_updates"):
        dataclasses.replace(config, max_updates=-1)


def test_reinforce_raises_the_goals_of_episodes_that_succeeded(tiny_dataset, tmp_path, monkeypatch):
    config = dataclasses.replace(train_goal.PRESETS["tiny"], dataset=str(tiny_dataset), method="reinforce",
                                 bc_coef=0.0, rounds=1, batch=8, lr=1e-2)
    trainer = train_goal.GoalTrainer(config, tmp_path, progress=False)
    rng = np.random.default_rng(0)
    window = (rng.random((len(mapping.CHANNELS), mapping.WINDOW, mapping.WINDOW)) < 0.2).astype(np.uint8)
    good, bad = 3 * mapping.WINDOW + 5, 20 * mapping.WINDOW + 9
    # Two episodes of one node on the same map: the first chose `good` and succeeded, the second `bad` and failed.
    fresh = {"maps": np.stack([np.packbits(window)] * 4), "node": np.full(4, 2),
             "label": np.array([good, good, bad, bad]),
             "choice": np.array([good, -1, bad, -1]), "episode": np.array([0, 0, 1, 1]),
             "success": np.array([True, False]), "teacher": np.array([False, False])}
    monkeypatch.setattr(trainer, "_collect", lambda: fresh)

    def gap():
        with torch.no_grad():
            logits = trainer.model(torch.as_tensor(window[None]), torch.tensor([2]))[0]
        return float(logits[good] - logits[bad])

    before = gap()
    row = trainer.iterate()
    assert gap() > before and row["learner_success"] == 0.5
    with pytest.raises(ValueError, match="method 'ppo'"):
        dataclasses.replace(config, method="ppo")
    with pytest.raises(ValueError, match="init_from"):
        trainer.warm_start(goal_policy.DEFAULT_DIR)  # the shipped network reads 40x30 maps, this run 24x18


def test_reinforce_clips_how_far_a_round_pushes_a_failed_goal_down(tiny_dataset, tmp_path):
    rng = np.random.default_rng(0)
    window = (rng.random((len(mapping.CHANNELS), mapping.WINDOW, mapping.WINDOW)) < 0.2).astype(np.uint8)
    good, bad = 3 * mapping.WINDOW + 5, 20 * mapping.WINDOW + 9
    # One episode chose `good` and succeeded; 39 steps of another chose `bad` and failed: ten updates push `bad` down.
    n = 40
    fresh = {"maps": np.stack([np.packbits(window)] * n), "node": np.full(n, 2), "label": np.full(n, good),
             "choice": np.array([good] + [bad] * (n - 1)), "episode": np.array([0] + [1] * (n - 1)),
             "success": np.array([True, False]), "teacher": np.zeros(n, bool)}

    def drop(clip):
        config = dataclasses.replace(train_goal.PRESETS["tiny"], dataset=str(tiny_dataset), method="reinforce",
                                     bc_coef=0.0, rounds=1, batch=4, lr=1e-3, clip=clip)
        trainer = train_goal.GoalTrainer(config, tmp_path / str(clip), progress=False)
        trainer._collect = lambda: fresh

        def logp():
            with torch.no_grad():
                logits = trainer.model(torch.as_tensor(window[None]), torch.tensor([2]))[0]
            return float(torch.log_softmax(logits / config.temperature, 0)[bad])

        before = logp()
        trainer.iterate()
        return before - logp()

    plain, clipped = drop(0.0), drop(0.2)
    assert plain > 10 and 0 < clipped < 3  # unclipped, the failed goal's log-probability runs away
    with pytest.raises(ValueError, match="clip 1.0"):
        dataclasses.replace(train_goal.PRESETS["tiny"], clip=1.0)


def test_mu_s_a_network_reading_the_room_bits_trains_acts_on_them_and_is_found_in_a_folder(
        tiny_dataset, tmp_path, env):
    from leaps_mj.learning import policies, policy_folder

    config = dataclasses.replace(train_goal.PRESETS["tiny"], dataset=str(tiny_dataset), rounds=2, episodes=2,
                                 room_bits=True)
    aug = tmp_path / "folder" / policy_folder.AUGMENTED
    train_goal.GoalTrainer(config, aug, progress=False).train()
    data = np.load(aug / "data" / "round_001.npz")
    assert data["bits"].shape == (len(data["label"]), rooms.NUM_ROOM_TYPES) and data["bits"].any()
    mu_s = policy_folder.load_augmented(tmp_path / "folder")
    assert isinstance(mu_s, goal_policy.GoalSubPolicy) and mu_s.net.config.room_bits
    ts = env.reset()
    mu_s.reset(env.episode.target)
    assert 0 <= mu_s.act(ts) < rooms.NUM_ACTIONS
    # The bits reach the goal: the same map with other bits scores the cells differently.
    maps, node = torch.zeros(1, mu_s.net.config.input_channels, mapping.WINDOW, mapping.WINDOW), torch.tensor([0])
    bits = torch.zeros(1, rooms.NUM_ROOM_TYPES)
    assert not torch.equal(mu_s.net(maps, node, bits), mu_s.net(maps, node, bits + 1))
    with pytest.raises(ValueError, match="room-type bits missing"):
        mu_s.net(maps, node)
    with pytest.raises(ValueError, match="room-type bits given"):
        nets.GoalNet(nets.GoalNetConfig(width=W, height=H))(maps[:, :6], node, bits)
    with pytest.raises(ValueError, match="bits has shape"):
        mu_s.net(maps, node, bits[:, :3])
    # A folder without its own μ_s falls back on the shipped one; a bit-blind network is refused as μ_s.
    assert isinstance(policy_folder.load_augmented(tmp_path), policies.LearnedSubPolicy)
    blind = tmp_path / "blind" / policy_folder.AUGMENTED
    train_goal.GoalTrainer(dataclasses.replace(config, rounds=1, room_bits=False), blind, progress=False).train()
    with pytest.raises(ValueError, match="does not read the room-type bits"):
        policy_folder.load_augmented(tmp_path / "blind")


def test_the_shipped_checkpoints_stay_within_20_mb():
    sizes = {p: p.stat().st_size for p in rooms.DATA_DIR.rglob("*.pt")}
    assert goal_policy.DEFAULT_DIR / goal_policy.GOAL in sizes
    assert sum(sizes.values()) <= 20 * 2 ** 20, {str(p): s for p, s in sizes.items()}


def test_descending_the_teachers_potential_leads_where_the_teachers_goal_lies(tiny_dataset):
    """The potential labels: int8 quarter metres in range, high in walls; the decoder's walk down them
    ends near the teacher's goal (both lie about 3 m down the way to the target)."""
    env = leaps_mj.load(str(tiny_dataset), "train", seed=0, width=W, height=H, horizon=60, max_start_doors=1)
    teacher = goal_teacher.TeacherGoals(env)
    agent = registry.make_agent("oracle-map", env, seed=0)
    agent.width, agent.height = W, H
    low, high = (round(v / mapping.CELL) for v in goal_teacher.POTENTIAL_RANGE)
    near = checked = 0
    for _ in range(3):
        ts = env.reset()
        agent.reset(env.episode.target)
        while not ts.last():
            action = agent.step(ts)
            cell, potential = teacher.labels(agent.driver.mapper, agent.driver.pose, potential=True)
            assert cell == teacher.cell(agent.driver.mapper, agent.driver.pose)
            assert potential.shape == (mapping.WINDOW, mapping.WINDOW) and potential.dtype == np.int8
            assert low <= potential.min() and potential.max() <= high and (potential == high).any()
            # Relative to the agent, also where its own grid cell is not free (beside a wall or furniture).
            centre = slice(mapping.WINDOW // 2 - 1, mapping.WINDOW // 2 + 2)
            assert np.abs(potential[centre, centre]).min() <= 1
            row, col = divmod(goal_teacher.potential_goal(potential), mapping.WINDOW)
            goal_row, goal_col = divmod(cell, mapping.WINDOW)
            near += math.hypot(row - goal_row, col - goal_col) <= 6
            checked += 1
            ts = env.step(action)
    assert near >= 0.8 * checked
    assert teacher.labels(agent.driver.mapper, agent.driver.pose, potential=False)[1] is None
    env.close()


def test_a_bf16_learner_trains_float32_weights_near_the_fp32_learners(tiny_dataset, tmp_path):
    with pytest.raises(ValueError, match="precision 'fp16'"):
        train_goal.GoalTrainConfig(precision="fp16")
    config = dataclasses.replace(train_goal.PRESETS["tiny"], dataset=str(tiny_dataset), rounds=1, episodes=2,
                                 potential=True)
    weights = {}
    for precision in ("fp32", "bf16"):
        trainer = train_goal.GoalTrainer(dataclasses.replace(config, precision=precision), tmp_path / precision,
                                         progress=False)
        trainer.train()
        weights[precision] = torch.cat([p.detach().flatten() for p in trainer.model.parameters()])
        assert {p.dtype for p in trainer.model.parameters()} == {torch.float32}
        assert all(s["exp_avg"].dtype == torch.float32 for s in trainer.optimizer.state.values())
    torch.manual_seed(config.seed)  # the trainer's initial weights
    start = torch.cat([p.detach().flatten() for p in nets.GoalNet(config.net_config).parameters()])
    # Same data, same draws: bf16 rounding moves the weights a little, far less than training moved them.
    moved, apart = (weights["fp32"] - start).norm(), (weights["bf16"] - weights["fp32"]).norm()
    assert 0 < apart < 0.5 * moved, (apart, moved)


def test_a_conv_goal_head_scores_every_cell_with_the_same_weights(tiny_dataset, tmp_path):
    with pytest.raises(ValueError, match="goal_head 'deconv'"):
        nets.GoalNetConfig(goal_head="deconv")
    with pytest.raises(ValueError, match="goal_head 'deconv'"):
        train_goal.GoalTrainConfig(goal_head="deconv")
    torch.manual_seed(0)
    config = nets.GoalNetConfig(width=W, height=H, goal_head="conv", potential=True, decoder="conv")
    net = nets.GoalNet(config)
    assert isinstance(net.out, torch.nn.Conv2d) and net.out.weight.numel() < 1000  # not one weight row per cell
    maps = torch.zeros(2, config.input_channels, mapping.WINDOW, mapping.WINDOW)
    maps[0, mapping.CHANNELS.index("door"), 4:6, 4:6] = 1
    logits, potential = net.heads(maps, torch.tensor([0, 3]))
    assert logits.shape == potential.shape == (2, mapping.WINDOW ** 2)
    # The same door placed elsewhere moves where the logits change: the head reads the map where it lies.
    shifted = torch.zeros_like(maps[:1])
    shifted[0, mapping.CHANNELS.index("door"), 20:22, 20:22] = 1
    blank = net(torch.zeros_like(maps[:1]), torch.tensor([0]))
    change = (net(maps[:1], torch.tensor([0])) - blank).abs().reshape(mapping.WINDOW, mapping.WINDOW)
    change2 = (net(shifted, torch.tensor([0])) - blank).abs().reshape(mapping.WINDOW, mapping.WINDOW)
    assert change[:12, :12].sum() > change[20:, 20:].sum() and change2[14:, 14:].sum() > change2[:8, :8].sum()
    # It trains and acts as the sub-policy like the linear head (the tiny preset: seconds).
    run = dataclasses.replace(train_goal.PRESETS["tiny"], dataset=str(tiny_dataset), goal_head="conv")
    trainer = train_goal.GoalTrainer(run, tmp_path / "run", progress=False)
    trainer.train()
    policy = goal_policy.GoalSubPolicy(tmp_path / "run")
    assert policy.net.config.goal_head == "conv"


def test_a_network_with_a_potential_head_descends_it_to_its_goal(env):
    config = nets.GoalNetConfig(width=W, height=H, potential=True, goals="potential")
    net = nets.GoalNet(config)
    maps = torch.zeros(2, len(mapping.CHANNELS), mapping.WINDOW, mapping.WINDOW)
    logits, potential = net.heads(maps, torch.tensor([0, 3]))
    assert logits.shape == potential.shape == (2, mapping.WINDOW ** 2)
    torch.testing.assert_close(net(maps, torch.tensor([0, 3])), logits)
    assert nets.GoalNet(nets.GoalNetConfig(width=W, height=H)).heads(maps, torch.tensor([0, 3]))[1] is None
    with pytest.raises(ValueError, match="potential must be a bool"):
        nets.GoalNetConfig(potential=1)
    with pytest.raises(ValueError, match="expected potential True"):
        nets.GoalNetConfig(goals="potential")
    with pytest.raises(ValueError, match="goals 'map'"):
        nets.GoalNetConfig(potential=True, goals="map")
    conv = nets.GoalNet(dataclasses.replace(config, decoder="conv", context=True, semantic=True, room_bits=True))
    maps2 = torch.zeros(2, conv.config.input_channels, mapping.WINDOW, mapping.WINDOW)
    potential = conv.heads(maps2, torch.tensor([0, 3]), torch.zeros(2, rooms.NUM_ROOM_TYPES))[1]
    assert potential.shape == (2, mapping.WINDOW ** 2)
    with pytest.raises(ValueError, match="decoder 'conv' decodes the potential head"):
        nets.GoalNetConfig(decoder="conv")
    with pytest.raises(ValueError, match="decoder 'unet'"):
        nets.GoalNetConfig(potential=True, decoder="unet")
    # A potential falling towards the row ahead and the left: the goal is DESCENT diagonal steps up-left,
    # wherever the goal logits point.
    rows, cols = np.divmod(np.arange(mapping.WINDOW ** 2), mapping.WINDOW)
    with torch.no_grad():
        net.potential.weight.zero_()
        net.potential.bias.copy_(torch.as_tensor(rows + cols, dtype=torch.float32))
        net.out.weight.zero_()
        net.out.bias.zero_()
        net.out.bias[0] = 10.0
    driver = map_navigation.GoalDriver("kitchen", W, H)
    window = _empty_step(driver, np.zeros(3))
    centre = mapping.WINDOW // 2 - goal_teacher.DESCENT
    assert goal_policy.choose_goal(net, driver, window) == centre * mapping.WINDOW + centre
    for config in (nets.GoalNetConfig(width=W, height=H), dataclasses.replace(config, goals="logits")):
        other = nets.GoalNet(config)  # goals from the logits: the potential head, if any, only trains
        with torch.no_grad():
            other.out.bias[7] = 10.0
        assert goal_policy.choose_goal(other, driver, window) == 7


def test_the_trainer_regresses_the_potential_turned_with_the_map(tiny_dataset, tmp_path, load_tool, capsys):
    config = dataclasses.replace(train_goal.PRESETS["tiny"], dataset=str(tiny_dataset), potential=True, mirror=True,
                                 rotate=True)
    trainer = train_goal.GoalTrainer(config, tmp_path, progress=False)
    trainer.train()
    data = np.load(tmp_path / "data" / "round_001.npz")
    assert data["potential"].shape == (len(data["label"]), mapping.WINDOW, mapping.WINDOW)
    with open(tmp_path / "progress.csv") as f:
        rows = list(train_goal.csv.DictReader(f))
    assert all(float(r["potential_loss"]) > 0 for r in rows)
    net, _ = goal_policy.load_goal_net(tmp_path / goal_policy.GOAL)
    assert net.config.potential and goal_policy.GoalSubPolicy(tmp_path).net.config.potential
    # The potential rides as the map's last channel through the symmetries: a marked cell moves with the goal.
    potential = torch.zeros(1, 1, mapping.WINDOW, mapping.WINDOW)
    potential[0, 0, 2, 5] = -8.0
    label = torch.tensor([2 * mapping.WINDOW + 5])
    turned, moved = train_goal.rotate(*train_goal.mirror(potential, label, torch.tensor([True])), torch.tensor([1]))
    assert turned.flatten()[moved].item() == -8.0
    # tools/potential_maps.py draws the labels and the prediction, and scores the walk down each.
    tool = load_tool("potential_maps")
    out = tmp_path / "maps.png"
    assert tool.main(["--data", str(tmp_path / "data" / "round_001.npz"), "--net", f"tiny={tmp_path / 'goal.pt'}",
                      "--samples", "2", "--out", str(out)]) == 0
    assert out.stat().st_size > 10_000 and "| labels | 0 |" in capsys.readouterr().out
    with pytest.raises(SystemExit):
        tool.main(["--data", str(tmp_path / "data" / "round_001.npz"), "--net", "tiny", "--out", str(out)])
    with pytest.raises(ValueError, match="potential True with method 'reinforce'"):
        dataclasses.replace(config, method="reinforce")
    with pytest.raises(ValueError, match="potential_coef -1"):
        dataclasses.replace(config, potential_coef=-1.0)


def test_the_potential_loss_is_smooth_l1_at_the_median_and_fits_other_quantiles():
    labels = torch.tensor([0.0, 10.0] * 50)  # two ways on, equally likely: 0 or 10 m farther
    torch.testing.assert_close(train_goal.potential_loss(torch.zeros(100), labels, 0.5),
                               torch.nn.functional.smooth_l1_loss(torch.zeros(100), labels))
    for quantile, expected in ((0.2, 0.0), (0.8, 10.0)):  # optimistic: the nearer way; pessimistic: the farther
        values = torch.linspace(-2.0, 12.0, 141)
        losses = [train_goal.potential_loss(v.expand(100), labels, quantile).item() for v in values]
        assert abs(values[int(np.argmin(losses))].item() - expected) < 0.11
    with pytest.raises(ValueError, match="potential_quantile 1.0"):
        train_goal.GoalTrainConfig(potential_quantile=1.0)


def test_progress_credit_gives_each_choice_the_metres_its_walk_bought():
    # Episode 0 (node 2): choices at steps 0 and 2; 5 -> 4 m under the first, 4 -> 3 m under the second.
    # Episode 1 (node 2): one choice at step 0 that walked away, 5 -> 6 m.
    samples = {"choice": np.array([7, -1, 9, -1, 4, -1]), "episode": np.array([0, 0, 0, 0, 1, 1]),
               "node": np.full(6, 2), "distance": np.array([5.0, 4.5, 4.0, 3.5, 5.0, 5.5], np.float32),
               "final_distance": np.array([3.0, 6.0], np.float32), "success": np.array([True, False])}
    gamma = 0.5
    returns = np.array([1.0 + gamma * 1.0, 1.0, -1.0])  # discounted progress from each choice on
    expected = np.zeros(6)
    expected[[0, 2, 4]] = (returns - returns.mean()) / (returns - returns.mean()).std()
    np.testing.assert_allclose(credit.choice_advantages(samples, "progress", gamma), expected)
    # The episode credit shares one success bit, minus the node's mean, among all steps of the episode.
    np.testing.assert_allclose(credit.choice_advantages(samples, "episode", gamma), [0.5] * 4 + [-0.5] * 2)
    with pytest.raises(ValueError, match="credit 'value'"):
        dataclasses.replace(train_goal.PRESETS["tiny"], credit="value")
    with pytest.raises(ValueError, match="credit_gamma 1.5"):
        dataclasses.replace(train_goal.PRESETS["tiny"], credit_gamma=1.5)


def test_min_start_distance_reaches_the_training_episodes(tiny_dataset):
    config = dataclasses.replace(train_goal.PRESETS["tiny"], dataset=str(tiny_dataset), min_start_distance=3.0,
                                 max_start_distance=13.0, episodes=2)
    samples = train_goal.collect(config, str(tiny_dataset / "train"), seed=0, episodes=2, beta=1.0, state_dict=None)
    first = np.flatnonzero(np.diff(samples["episode"], prepend=-1))  # each episode's first step
    assert (samples["distance"][first] >= 3.0).all()  # without the option the first start is 2.0 m away
    mixed = train_goal.collect(dataclasses.replace(config, far_fraction=0.5), str(tiny_dataset / "train"), seed=0,
                               episodes=8, beta=1.0, state_dict=None)
    first = np.flatnonzero(np.diff(mixed["episode"], prepend=-1))
    assert (mixed["distance"][first] >= 3.0).any() and (mixed["distance"][first] < 3.0).any()
    with pytest.raises(ValueError, match="min_start_distance 13.0"):
        dataclasses.replace(train_goal.PRESETS["tiny"], min_start_distance=13.0)
    with pytest.raises(ValueError, match="far_fraction 0"):
        dataclasses.replace(train_goal.PRESETS["tiny"], far_fraction=0.0)


def test_init_data_trains_a_new_run_on_another_runs_dataset_and_its_own(tiny_dataset, tmp_path):
    config = dataclasses.replace(train_goal.PRESETS["tiny"], dataset=str(tiny_dataset), rounds=1, episodes=2)
    source = train_goal.GoalTrainer(config, tmp_path / "source", progress=False)
    source.train()
    train_goal.GoalTrainer(dataclasses.replace(config, seed=2), tmp_path / "other", progress=False).train()
    source_samples = sum(len(np.load(tmp_path / run / "data" / "round_000.npz")["label"])
                         for run in ("source", "other"))
    pooled = f"{tmp_path / 'source'},{tmp_path / 'other'}"
    continued = train_goal.GoalTrainer(dataclasses.replace(config, init_data=pooled, seed=1),
                                       tmp_path / "continued", progress=False)
    continued.train()
    own = len(np.load(tmp_path / "continued" / "data" / "round_000.npz")["label"])
    rows = list(csv.DictReader(open(tmp_path / "continued" / "progress.csv")))
    assert int(rows[-1]["samples"]) == source_samples + own and own > 0
    with pytest.raises(ValueError, match="init_data .*continued/data'.*data/round_"):
        dataclasses.replace(config, init_data=f"{tmp_path / 'source'},{tmp_path / 'continued' / 'data'}")
    wider = train_goal.GoalTrainer(dataclasses.replace(config, init_data=str(tmp_path / "source"), context=True),
                                   tmp_path / "wider", progress=False)
    with pytest.raises(ValueError, match="round_000.npz: holds samples"):
        wider.train()
