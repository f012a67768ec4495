"""The CNN room-type classifier at test time: panoramas, the confidence filter, an env wrapper.

The paper's alternative to ground-truth semantic bits: a
:class:`leaps_mj.learning.nets.RoomClassifier` looks at 4 first-person views 90°
apart (a panorama taken by turning the agent's camera on the spot) and gives
a probability per room type. For ``outdoor`` it looks at the last 4 frames of
the trajectory instead (a panorama taken in a yard sees the house walls as
often as open space). A bit turns on only while the classifier's probability
has been at least :data:`CONFIDENCE` for :data:`CONSECUTIVE` consecutive
steps, and turns off as soon as it drops below.

:class:`ClassifierBits` wraps a :class:`leaps_mj.environment.roomnav.RoomNavEnvironment` so
that ``observation["semantic"]`` holds these bits instead of the ground truth;
everything else passes through, so any agent (LEAPS, the controller) runs on
the classifier's bits unchanged. The views are resampled (nearest pixel) to
the classifier's resolution, so a classifier trained at 40x30 serves an
environment rendering at 120x90: the pixel centres of the 40x30 grid are
pixel centres of the 120x90 one.
"""

from __future__ import annotations

import collections
import math
import os
import pathlib

import dm_env
import numpy as np
import torch

from leaps_mj.environment import roomnav as env_lib
from leaps_mj.learning import checkpoints, nets
from leaps_mj.world import rooms

#: Probability a bit needs (paper: 0.85) ...
CONFIDENCE = 0.85
#: ... for this many consecutive steps (paper: 3) to turn on.
CONSECUTIVE = 3
#: Views per classifier input: the panorama's 4 headings, or the last 4 frames.
NUM_VIEWS = 4
#: Index of the room type classified from the last frames rather than the panorama.
OUTDOOR = rooms.room_index("outdoor")
#: How :class:`ClassifierBits` may combine its bits with the ground truth, for the ablations that
#: explain Fig. 6: None (the classifier alone), "and" (its bits the truth confirms: false positives
#: dropped) or "or" (its bits and the truth: misses filled in).
TRUTH_MODES = (None, "and", "or")
#: The shipped classifier (cpu preset, 40x30 views).
DEFAULT_PATH = rooms.DATA_DIR / "classifier" / "cpu.pt"
#: The command that trains it.
TRAIN_COMMAND = (f"python -m leaps_mj.train classifier --preset cpu --out runs/classifier_cpu && "
                 f"cp runs/classifier_cpu/classifier.pt {DEFAULT_PATH}")


def panorama(env) -> tuple[np.ndarray, np.ndarray]:
    """Four views from the agent's position at its heading + 0°, 90°, 180°, 270° (counter-clockwise).

    Turns the agent in place through the physics, renders with the
    environment's renderer, and puts the pose back: the episode is not
    changed (the task keeps the observation it rendered at the real pose).

    Args:
      env: a :class:`leaps_mj.environment.roomnav.RoomNavEnvironment` in an episode.

    Returns:
      segmentation (4, H, W) uint8 class ids and depth (4, H, W) float32
      metres (clipped at :data:`leaps_mj.environment.roomnav.MAX_DEPTH`), at the environment's resolution.
    """
    physics = env.physics
    pose = physics.agent_pose()
    class_lut = env.segment_luts[0]
    segs, depths = [], []
    try:
        for k in range(NUM_VIEWS):
            yaw = math.remainder(float(pose[2]) + k * math.pi / 2, 2 * math.pi)
            physics.set_agent_pose((pose[0], pose[1], yaw))
            seg, depth = env.renderer.render_segments(physics.data.ptr)
            segs.append(class_lut[seg])
            depths.append(np.minimum(depth, env_lib.MAX_DEPTH))
    finally:
        physics.set_agent_pose(pose)
    return np.stack(segs), np.stack(depths).astype(np.float32)


def resample(frames: np.ndarray, width: int, height: int) -> np.ndarray:
    """Nearest-pixel resampling of (..., H, W) frames to (..., height, width).

    Each output pixel takes the input pixel containing its centre, so a
    downscale by an integer factor keeps exactly the pixels a render at the
    lower resolution would have sampled.
    """
    frames = np.asarray(frames)
    h, w = frames.shape[-2:]
    if (h, w) == (height, width):
        return frames
    rows = ((np.arange(height) + 0.5) * h / height).astype(np.int64)
    cols = ((np.arange(width) + 0.5) * w / width).astype(np.int64)
    return frames[..., rows[:, None], cols[None, :]]


class BitFilter:
    """Turns per-step probabilities into bits: on after ``steps`` consecutive steps at ``threshold`` or more.

    Args:
      threshold: confidence a bit needs (paper 0.85).
      steps: consecutive steps it needs it for (paper 3).
      num_bits: number of room types.
    """

    def __init__(self, threshold: float = CONFIDENCE, steps: int = CONSECUTIVE,
                 num_bits: int = rooms.NUM_ROOM_TYPES):
        if not 0.0 < threshold <= 1.0:
            raise ValueError(f"threshold {threshold!r}: expected a probability in (0, 1]")
        if isinstance(steps, bool) or not isinstance(steps, int) or steps < 1:
            raise ValueError(f"steps {steps!r}: expected a positive integer")
        self.threshold = threshold
        self.steps = steps
        self.streak = np.zeros(num_bits, dtype=np.int64)

    def reset(self) -> None:
        """Forgets the streaks (a new episode)."""
        self.streak[:] = 0

    def update(self, probabilities) -> np.ndarray:
        """The bits (uint8) after one more step's probabilities.

        Raises:
          ValueError: for probabilities of the wrong shape.
        """
        p = np.asarray(probabilities, dtype=np.float64)
        if p.shape != self.streak.shape:
            raise ValueError(f"probabilities of shape {p.shape}; expected {self.streak.shape}")
        self.streak = np.where(p >= self.threshold, self.streak + 1, 0)
        return (self.streak >= self.steps).astype(np.uint8)


class RoomTypeClassifier:
    """A trained :class:`leaps_mj.learning.nets.RoomClassifier` with the panorama / last-frames split.

    Args:
      model: the network (put in eval mode).

    Attributes:
      width, height: the resolution of the views the network takes.
    """

    def __init__(self, model: nets.RoomClassifier):
        if not isinstance(model, nets.RoomClassifier):
            raise ValueError(f"model is a {type(model).__name__}; expected a nets.RoomClassifier")
        if model.config.num_views != NUM_VIEWS:
            raise ValueError(f"model takes {model.config.num_views} views; expected {NUM_VIEWS}")
        self.model = model.eval()
        self.width, self.height = model.config.width, model.config.height

    @classmethod
    def load(cls, path: str | os.PathLike = DEFAULT_PATH) -> "RoomTypeClassifier":
        """Loads a checkpoint written by ``python -m leaps_mj.train classifier``.

        Raises:
          ValueError: if the file is missing (naming the command that trains the
            shipped one), unreadable or not a room classifier.
        """
        path = pathlib.Path(path)
        if not path.is_file():
            hint = f"; train it with `{TRAIN_COMMAND}`" if path == DEFAULT_PATH else ""
            raise ValueError(f"no classifier checkpoint {str(path)!r}{hint}")
        model, _, _ = checkpoints.load_policy(path)
        return cls(model)

    @torch.no_grad()
    def logits(self, seg: np.ndarray, depth: np.ndarray) -> np.ndarray:
        """Logits (B, K) of batches of 4 views (B, 4, H, W) at any resolution (resampled)."""
        seg = resample(seg, self.width, self.height)
        depth = resample(depth, self.width, self.height)
        x = nets.ActorCritic.preprocess({"segmentation": seg, "depth": depth})
        return self.model(x["segmentation"], x["depth"]).numpy()

    def probabilities(self, pano: tuple[np.ndarray, np.ndarray],
                      frames: tuple[np.ndarray, np.ndarray]) -> np.ndarray:
        """Probability (K,) of each room type: outdoor from the last frames, the others from the panorama.

        Args:
          pano: segmentation and depth (4, H, W) of a :func:`panorama`.
          frames: segmentation and depth (4, H, W) of the last 4 observations, oldest first.
        """
        views = [np.stack([pano[i], frames[i]]) for i in range(2)]  # (2, 4, H, W) each
        logits = self.logits(*views)
        probs = 1.0 / (1.0 + np.exp(-logits[0]))
        probs[OUTDOOR] = 1.0 / (1.0 + np.exp(-logits[1, OUTDOOR]))
        return probs


class ClassifierBits(dm_env.Environment):
    """A RoomNav environment whose ``observation["semantic"]`` comes from the room classifier.

    Every time step (FIRST included) it takes a :func:`panorama`, keeps the
    last 4 observed frames (the first frame repeated until there are 4),
    runs the classifier and passes its probabilities through a
    :class:`BitFilter`. Everything else of the time step, and every other
    attribute of the environment (``task``, ``physics``, ``config``,
    ``reset_to`` ...), is the wrapped environment's.

    Args:
      env: a :class:`leaps_mj.environment.roomnav.RoomNavEnvironment` rendering pixels.
      model: a :class:`RoomTypeClassifier` (default: the shipped one).
      threshold, steps: the filter's confidence and run length.
      truth: one of :data:`TRUTH_MODES`: None for the classifier's bits; "and" or "or" combine them
        with the task's ground-truth bits (diagnostic: which of the classifier's errors move LEAPS).

    Raises:
      ValueError: for an environment without pixels or an unknown ``truth``.

    Attributes:
      probabilities: the classifier's probabilities (K,) at the last time step.
    """

    def __init__(self, env, model: RoomTypeClassifier | None = None, threshold: float = CONFIDENCE,
                 steps: int = CONSECUTIVE, truth: str | None = None):
        if not env.config.pixels:
            raise ValueError("ClassifierBits needs an environment rendering pixels (pixels=True)")
        if truth not in TRUTH_MODES:
            raise ValueError(f"truth {truth!r}: expected one of {list(TRUTH_MODES)}")
        self.truth = truth
        self._env = env
        self.model = model if model is not None else RoomTypeClassifier.load()
        self.filter = BitFilter(threshold, steps)
        self._frames: collections.deque = collections.deque(maxlen=NUM_VIEWS)
        self.probabilities = np.zeros(rooms.NUM_ROOM_TYPES)

    def __getattr__(self, name):
        if name.startswith("_"):
            raise AttributeError(name)
        return getattr(self._env, name)

    def _bits(self, ts: dm_env.TimeStep) -> dm_env.TimeStep:
        obs = ts.observation
        if ts.first():
            self.filter.reset()
            self._frames.clear()
        frame = (obs["segmentation"], obs["depth"])
        while len(self._frames) < NUM_VIEWS - 1:
            self._frames.append(frame)
        self._frames.append(frame)
        frames = tuple(np.stack([f[i] for f in self._frames]) for i in range(2))
        self.probabilities = self.model.probabilities(panorama(self._env), frames)
        obs = collections.OrderedDict(obs)
        bits = self.filter.update(self.probabilities)
        if self.truth == "and":
            bits &= np.asarray(self._env.task.bits, np.uint8)
        elif self.truth == "or":
            bits |= np.asarray(self._env.task.bits, np.uint8)
        obs["semantic"] = bits
        return ts._replace(observation=obs)

    def reset(self) -> dm_env.TimeStep:
        return self._bits(self._env.reset())

    def reset_to(self, spec) -> dm_env.TimeStep:
        """Starts a fixed episode (see :meth:`leaps_mj.environment.roomnav.RoomNavEnvironment.reset_to`)."""
        return self._bits(self._env.reset_to(spec))

    def step(self, action) -> dm_env.TimeStep:
        return self._bits(self._env.step(action))

    def observation_spec(self):
        return self._env.observation_spec()

    def action_spec(self):
        return self._env.action_spec()

    def close(self) -> None:
        self._env.close()


class BitAgreement:
    """An episode observer (see :func:`leaps_mj.evaluation.harness.run_episode`) scoring the bits an agent saw against the truth.

    Run episodes on a :class:`ClassifierBits` environment with it: every
    step it compares ``timestep.observation["semantic"]`` with the task's
    ground-truth bits and counts, per room type, true positives, false
    positives and false negatives, and the steps on which all bits agree.
    """

    def __init__(self):
        self.steps = 0
        self.exact = 0
        self.tp = np.zeros(rooms.NUM_ROOM_TYPES, dtype=np.int64)
        self.fp = np.zeros_like(self.tp)
        self.fn = np.zeros_like(self.tp)
        self._task = None

    def begin(self, env, spec, agent) -> None:
        del spec, agent
        self._task = env.task

    def step(self, timestep, action, info) -> None:
        del action, info
        seen = np.asarray(timestep.observation["semantic"], dtype=bool)
        truth = np.asarray(self._task.bits, dtype=bool)
        self.steps += 1
        self.exact += bool(np.array_equal(seen, truth))
        self.tp += seen & truth
        self.fp += seen & ~truth
        self.fn += ~seen & truth

    def end(self, result) -> None:
        del result

    def summary(self) -> dict:
        """``{"steps", "exact", "types": {type: {"truth_steps", "precision", "recall"}}}`` (nan where undefined)."""
        def ratio(a, b):
            return float(a / b) if b else float("nan")

        return {"steps": self.steps, "exact": ratio(self.exact, self.steps), "types": {
            t: {"truth_steps": int(self.tp[k] + self.fn[k]), "precision": ratio(self.tp[k], self.tp[k] + self.fp[k]),
                "recall": ratio(self.tp[k], self.tp[k] + self.fn[k])} for k, t in enumerate(rooms.ROOM_TYPES)}}
