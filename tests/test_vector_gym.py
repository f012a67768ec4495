"""Vectorised environments and the gymnasium adapter."""

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
        with pytest.raises(ValueError, match="worker 1: invalid action 12"):
            venv.step([0, 12])
        assert len(venv.step(np.array([0, 1], dtype=np.int32))) == 2  # still usable
        specs = venv.episodes()
        assert venv.reset_to(specs)[0].first()
        with pytest.raises(ValueError, match="got 3 actions"):
            venv.step([0, 0, 0])
    venv.close()  # idempotent


def test_gymnasium_adapter_passes_check_env(tiny_dataset):
    import leaps_mj.gym_adapter  # noqa: F401  (registers the id)

    env = gymnasium.make("leaps_mj/RoomNav-v1", dataset=str(tiny_dataset), split="train",
                         horizon=20, width=32, height=24)
    assert env.action_space == gymnasium.spaces.Discrete(9)
    check_env(env.unwrapped, skip_render_check=True)
    o1, _ = env.reset(seed=4)
    o2, _ = env.reset(seed=4)
    np.testing.assert_array_equal(o1["depth"], o2["depth"])
    env.close()
