"""Gymnasium adapter: RoomNav as a gymnasium environment through shimmy.

Importing this module registers ``leaps_mj/RoomNav-v1``::

    import gymnasium as gym
    env = gym.make("leaps_mj.gym_adapter:leaps_mj/RoomNav-v1", split="train", width=64, height=48)

Keyword arguments are those of :func:`leaps_mj.load`. ``reset(seed=…)``
reseeds the task's episode sampler (shimmy replaces its RandomState).
Observations are the dm_env dict; the action space is ``Discrete(9)``.
"""

import gymnasium
from shimmy.dm_control_compatibility import DmControlCompatibilityV0

from leaps_mj.environment import roomnav

ENV_ID = "leaps_mj/RoomNav-v1"


def make(render_mode=None, **kwargs) -> DmControlCompatibilityV0:
    """A gymnasium environment wrapping :func:`leaps_mj.load` (kwargs)."""
    return DmControlCompatibilityV0(roomnav.load(**kwargs), render_mode=render_mode)


if ENV_ID not in gymnasium.registry:
    gymnasium.register(ENV_ID, entry_point=make, disable_env_checker=True)
