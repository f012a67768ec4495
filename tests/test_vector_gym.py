"""Vectorised environments and the gymnasium adapter."""

import os

import gymnasium
import numpy as np
import pytest
from gymnasium.utils.env_checker import check_env

from leaps_mj.environment import vector


def test_vector_env_steps_in_workers_and_forwards_errors(tiny_dataset):
    with vector.VectorEnv(2, seed=0, dataset=str(tiny_dataset), split="train", horizon=5,
                          width=32, height=24) as venv:
        first = venv.reset()
        assert all(ts.first() for ts in first)
        assert vector.stack(first, "depth").shape == (2, 24, 32)
        kinds = []
        for _ in range(6):
            kinds.append([ts.step_type for ts in venv.step([8, 3])])
        assert kinds[4] == [2, 2] and kinds[5] == [0, 0]  # LAST at the horizon, then auto-reset
        with pytest.raises(ValueError, match="env 1: invalid action 12"):
            venv.step([0, 12])
        assert len(venv.step(np.array([0, 1], dtype=np.int32))) == 2  # still usable
        specs = venv.episodes()
        assert venv.reset_to(specs)[0].first()
        with pytest.raises(ValueError, match="got 3 actions"):
            venv.step([0, 0, 0])
    venv.close()  # idempotent


def test_vector_env_results_do_not_depend_on_the_grouping(tiny_dataset):
    kwargs = dict(dataset=str(tiny_dataset), split="train", horizon=6, width=32, height=24)
    runs = []
    for workers in (1, 3):
        with vector.VectorEnv(3, seed=2, num_workers=workers, **kwargs) as venv:
            assert venv.num_workers == workers
            steps = [venv.reset()] + [venv.step([k % 9, (k + 3) % 9, 8]) for k in range(8)]
            runs.append([(ts.step_type, ts.reward, ts.observation["segmentation"].copy(),
                          ts.observation["depth"].copy()) for batch in steps for ts in batch])
    for a, b in zip(*runs):
        assert a[0] == b[0] and a[1] == b[1]
        np.testing.assert_array_equal(a[2], b[2])
        np.testing.assert_array_equal(a[3], b[3])


def test_vector_env_async_steps_each_worker_alone_and_matches_the_lock_step(tiny_dataset):
    kwargs = dict(dataset=str(tiny_dataset), split="train", horizon=6, width=32, height=24)
    actions = lambda k: [k % 9, (k + 3) % 9, 8, (2 * k) % 9]  # noqa: E731
    with vector.VectorEnv(4, seed=2, num_workers=1, **kwargs) as venv:
        lock_step = [venv.reset()] + [venv.step(actions(k)) for k in range(8)]
    with vector.VectorEnv(4, seed=2, num_workers=2, pin=True, **kwargs) as venv:
        cpus = sorted(os.sched_getaffinity(0))
        assert [os.sched_getaffinity(p.pid) for p in venv._procs] == [{cpus[0]}, {cpus[1 % len(cpus)]}]
        venv.async_reset()
        steps = {0: [], 1: []}  # per worker: its time steps in order
        while min(len(v) for v in steps.values()) < 9:
            ids, timesteps = venv.recv()
            w = ids[0] // 2
            steps[w].append(timesteps)
            if len(steps[w]) < 9:
                k = len(steps[w]) - 1
                venv.send(ids, [actions(k)[i] for i in ids])
        with pytest.raises(RuntimeError, match="nothing pending"):
            venv.recv()
        venv.send([0, 1], [8, 8])
        with pytest.raises(RuntimeError, match="worker 0 .* still stepping"):
            venv.send([0, 1], [8, 8])
        with pytest.raises(RuntimeError, match="still stepping"):
            venv.step([8, 8, 8, 8])
        with pytest.raises(ValueError, match=r"env_ids \[1, 2\]: expected one worker's environments"):
            venv.send([1, 2], [8, 8])
        with pytest.raises(ValueError, match="got 1 actions"):
            venv.send([2, 3], [8])
    # Each environment's trajectory is the lock-step one, whichever worker finished first.
    for k in range(9):
        for i in range(4):
            a, b = lock_step[k][i], steps[i // 2][k][i % 2]
            assert a.step_type == b.step_type and a.reward == b.reward
            np.testing.assert_array_equal(a.observation["depth"], b.observation["depth"])


def test_vector_env_rejects_bad_worker_counts_and_frees_its_shared_memory(tiny_dataset):
    kwargs = dict(dataset=str(tiny_dataset), split="train", horizon=5, width=32, height=24)
    for bad in (0, 3, True):
        with pytest.raises(ValueError, match="num_workers"):
            vector.VectorEnv(2, num_workers=bad, **kwargs)
    venv = vector.VectorEnv(2, num_workers=1, **kwargs)
    names = [block.name for block in venv._blocks]
    assert names  # segmentation and depth travel through shared memory
    first = venv.reset()
    first[0].observation["depth"][:] = -1.0  # a copy: writing to it does not touch the env's frames
    assert (venv.step([8, 8])[0].observation["depth"] >= 0).all()
    venv.close()
    from multiprocessing import shared_memory

    for name in names:
        with pytest.raises(FileNotFoundError):
            shared_memory.SharedMemory(name=name)


def _gym_kwargs(tiny_dataset, **extra):
    return dict(dataset=str(tiny_dataset), split="train", horizon=20, width=40, height=36, **extra)


def test_gymnasium_adapter_passes_both_checkers(tiny_dataset):
    from stable_baselines3.common.env_checker import check_env as sb3_check_env

    import leaps_mj.gym_adapter  # noqa: F401  (registers the id)

    env = gymnasium.make("leaps_mj/RoomNav-v1", **_gym_kwargs(tiny_dataset))
    assert env.action_space == gymnasium.spaces.Discrete(9)
    assert env.spec.disable_env_checker is False
    space = env.observation_space
    assert space["segmentation"].shape == (36, 40, 1) and space["depth"].dtype == np.uint8
    assert space["collision"].shape == (1,) and "pose" not in space.spaces
    check_env(env.unwrapped, skip_render_check=True)
    sb3_check_env(env.unwrapped, warn=True)
    o1, info = env.reset(seed=4)
    o2, _ = env.reset(seed=4)
    np.testing.assert_array_equal(o1["depth"], o2["depth"])
    assert info["target"] in leaps_mj.world.rooms.GRAPH_NODES
    env.close()


def test_gymnasium_depth_is_quantised_with_the_documented_scale(tiny_dataset):
    from leaps_mj.environment import gym_adapter

    env = gym_adapter.RoomNavGym(include_pose=True, **_gym_kwargs(tiny_dataset))
    obs, _ = env.reset(seed=1)
    dm = env.unwrapped_dm_env
    metres = dm.reset_to(dm.episode).observation["depth"]  # the same start, seen by the dm_env side
    np.testing.assert_allclose(obs["depth"][..., 0] * gym_adapter.DEPTH_SCALE, metres,
                               atol=gym_adapter.DEPTH_SCALE / 2 + 1e-6)
    assert obs["pose"].shape == (3,) and env.observation_space.contains(obs)
    with pytest.raises(ValueError, match="render_mode"):
        gym_adapter.RoomNavGym(render_mode="human", **_gym_kwargs(tiny_dataset))
    env.close()


def test_stable_baselines3_ppo_learns_on_the_id(tiny_dataset):
    from stable_baselines3 import PPO

    import leaps_mj.gym_adapter  # noqa: F401

    env = gymnasium.make("leaps_mj/RoomNav-v1", **_gym_kwargs(tiny_dataset))
    model = PPO("MultiInputPolicy", env, n_steps=64, batch_size=32, n_epochs=1, seed=0, device="cpu")
    model.learn(128)
    action, _ = model.predict(env.reset(seed=0)[0], deterministic=True)
    assert env.action_space.contains(int(action))
    env.close()


def test_make_vec_steps_environments_in_workers(tiny_dataset):
    from leaps_mj.environment import gym_adapter

    with pytest.raises(ValueError, match="num_envs"):
        gym_adapter.make_vec(0)
    venv = gym_adapter.make_vec(2, seed=3, **_gym_kwargs(tiny_dataset))
    try:
        obs, infos = venv.reset(seed=3)
        assert obs["segmentation"].shape == (2, 36, 40, 1)
        obs, reward, terminated, truncated, _ = venv.step(np.array([0, 8]))
        assert reward.shape == (2,) and terminated.dtype == bool
    finally:
        venv.close()


def test_sb3_example_trains_saves_and_plots(tiny_dataset, tmp_path):
    import importlib.util
    import pathlib

    path = pathlib.Path(__file__).resolve().parent.parent / "examples" / "sb3_ppo.py"
    spec = importlib.util.spec_from_file_location("sb3_ppo", path)
    example = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(example)
    out = tmp_path / "ppo"
    argv = ["--steps", "256", "--num-envs", "1", "--n-steps", "64", "--dataset", str(tiny_dataset),
            "--width", "40", "--height", "36", "--horizon", "20", "--max-start", "4", "--out", str(out)]
    assert example.main(argv) == 0
    assert (out / "ppo_roomnav.zip").stat().st_size > 10_000
    rows = example.read_monitor(out)
    assert rows and sum(r["l"] for r in rows) <= 256
    assert (out / "learning_curve.png").stat().st_size > 5_000
