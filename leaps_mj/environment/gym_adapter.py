"""RoomNav as a gymnasium environment whose spaces mainstream RL libraries take as they are.

Importing this module registers ``leaps_mj/RoomNav-v1``::

    import gymnasium as gym
    env = gym.make("leaps_mj.gym_adapter:leaps_mj/RoomNav-v1", split="train", width=64, height=48)

Keyword arguments are those of :func:`leaps_mj.load`, plus ``include_pose``.
The dm_env environment keeps its own specs; this adapter reshapes them for
libraries such as Stable-Baselines3 and cleanrl, which recognise images by
their space (uint8, values 0–255, channel-last ``(H, W, C)``) and flatten
every other entry:

* ``segmentation``: ``Box(0, 255, (H, W, 1), uint8)``, the class id per pixel
  (0 .. 34; :data:`leaps_mj.world.rooms.SEG_CLASSES`);
* ``depth``: ``Box(0, 255, (H, W, 1), uint8)``, depth quantised to
  :data:`DEPTH_SCALE` metres per unit (0 .. 20 m), ``metres = value * DEPTH_SCALE``;
* ``semantic`` and ``target``: ``MultiBinary(8)`` (room-type bits, target one-hot);
* ``collision``: ``MultiBinary(1)``;
* ``pose`` (x, y, heading; privileged) only with ``include_pose=True``.

The action space is ``Discrete(9)``. ``reset(seed=...)`` reseeds the task's
episode sampler; episodes end ``terminated`` on success and ``truncated`` at
the horizon (dm_env discount 0 vs 1). gymnasium's environment checker runs
on :func:`gymnasium.make` as for any registered id. :func:`make_vec` gives
the vectorised form (one process per environment) for libraries that step
several at once.
"""

from __future__ import annotations

import gymnasium
import numpy as np
from gymnasium import spaces

from leaps_mj.environment import roomnav
from leaps_mj.world import rooms

ENV_ID = "leaps_mj/RoomNav-v1"
#: Metres per unit of the uint8 depth channel.
DEPTH_SCALE = roomnav.MAX_DEPTH / 255.0
#: Bounds of the privileged pose (metres, metres, radians).
_POSE_BOUND = np.array([1e3, 1e3, np.pi], np.float32)


class RoomNavGym(gymnasium.Env):
    """A :class:`leaps_mj.environment.roomnav.RoomNavEnvironment` behind the gymnasium API.

    Args:
      render_mode: None or "rgb_array" (the agent's RGB view; needs ``rgb=True``).
      include_pose: also observe the privileged pose.
      **kwargs: for :func:`leaps_mj.load` (dataset, split, seed, width, height, reward, horizon, ...).

    Raises:
      ValueError: for an unknown render mode, or "rgb_array" without ``rgb=True``.
    """

    metadata = {"render_modes": ["rgb_array"], "render_fps": 10}

    def __init__(self, render_mode: str | None = None, include_pose: bool = False, **kwargs):
        if render_mode not in (None, "rgb_array"):
            raise ValueError(f"render_mode {render_mode!r}: expected None or 'rgb_array'")
        if render_mode == "rgb_array" and not kwargs.get("rgb", False):
            raise ValueError("render_mode 'rgb_array' needs the RGB view: pass rgb=True")
        self.render_mode = render_mode
        self.include_pose = include_pose
        self._env = roomnav.load(**kwargs)
        c = self._env.config
        frame = (c.height, c.width, 1)
        entries = {
            "segmentation": spaces.Box(0, 255, frame, np.uint8),
            "depth": spaces.Box(0, 255, frame, np.uint8),
            "semantic": spaces.MultiBinary(rooms.NUM_ROOM_TYPES),
            "target": spaces.MultiBinary(rooms.NUM_ROOM_TYPES),
            "collision": spaces.MultiBinary(1),
        }
        if include_pose:
            entries["pose"] = spaces.Box(-_POSE_BOUND, _POSE_BOUND, (3,), np.float32)
        self.observation_space = spaces.Dict(entries)
        self.action_space = spaces.Discrete(rooms.NUM_ACTIONS)
        self._last_rgb = None

    @property
    def unwrapped_dm_env(self) -> roomnav.RoomNavEnvironment:
        """The dm_env environment underneath (episodes, house models, the task)."""
        return self._env

    def _observation(self, ts) -> dict:
        o = ts.observation
        obs = {
            "segmentation": o["segmentation"][..., None],
            "depth": np.rint(o["depth"] / DEPTH_SCALE).astype(np.uint8)[..., None],
            "semantic": o["semantic"].astype(np.int8),
            "target": o["target"].astype(np.int8),
            "collision": np.asarray(o["collision"], np.int8).reshape(1),
        }
        if self.include_pose:
            obs["pose"] = np.clip(o["pose"], -_POSE_BOUND, _POSE_BOUND).astype(np.float32)
        self._last_rgb = o.get("rgb")
        return obs

    def _info(self) -> dict:
        spec = self._env.episode
        return {"house": spec.house, "target": spec.target, "plan_length": spec.plan_length,
                "geodesic": spec.geodesic, "success": bool(self._env.task.success)}

    def reset(self, *, seed: int | None = None, options: dict | None = None):
        super().reset(seed=seed)
        if seed is not None:
            self._env.seed(seed)
        if options and "episode" in options:
            ts = self._env.reset_to(options["episode"])
        else:
            ts = self._env.reset()
        return self._observation(ts), self._info()

    def step(self, action):
        ts = self._env.step(int(action))
        terminated = ts.last() and ts.discount == 0.0
        truncated = ts.last() and not terminated
        return self._observation(ts), float(ts.reward), bool(terminated), bool(truncated), self._info()

    def render(self):
        return self._last_rgb if self.render_mode == "rgb_array" else None

    def close(self):
        self._env.close()


def make(render_mode=None, **kwargs) -> RoomNavGym:
    """The gymnasium environment of the registered id (kwargs as :class:`RoomNavGym`)."""
    return RoomNavGym(render_mode=render_mode, **kwargs)


def make_vec(num_envs: int, seed: int = 0, **kwargs) -> gymnasium.vector.AsyncVectorEnv:
    """``num_envs`` environments in worker processes (spawned: safe with GL), gymnasium's vector API.

    Environment ``i`` samples episodes with seed ``seed + i``; kwargs as :class:`RoomNavGym`.

    Raises:
      ValueError: for a bad ``num_envs``.
    """
    if isinstance(num_envs, bool) or not isinstance(num_envs, int) or num_envs < 1:
        raise ValueError(f"num_envs {num_envs!r}: expected a positive integer")
    fns = [_Maker(dict(kwargs, seed=seed + i)) for i in range(num_envs)]
    return gymnasium.vector.AsyncVectorEnv(fns, context="spawn")


class _Maker:
    """A picklable environment factory for worker processes."""

    def __init__(self, kwargs: dict):
        self.kwargs = kwargs

    def __call__(self) -> RoomNavGym:
        return RoomNavGym(**self.kwargs)


if ENV_ID not in gymnasium.registry:
    gymnasium.register(ENV_ID, entry_point=make)
