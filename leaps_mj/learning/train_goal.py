"""Train the map-goal sub-policy's network by DAgger in rounds over an aggregated dataset.

``python -m leaps_mj.train goal --out runs/goal`` (resumable: rerun the same command after a kill;
rerun it with more ``--rounds`` to extend a finished run)

Each round, worker processes run training episodes (hop-like: starts at
most ``max_start_doors`` doors from a room of the target, ``horizon`` steps,
every graph node) with :class:`leaps_mj.environment.map_navigation.GoalDriver`: at
each step the egocentric map is stored with the teacher's goal — the cell of
the map where the geodesic expert's path lies
:data:`leaps_mj.environment.goal_teacher.TEACHER_LOOKAHEAD` metres ahead (the agent's own cell once it stands where the target is seen)
— and the goals that drive the episode are the teacher's (round 0, then with
probability ``beta`` per episode) or the network's. The round's samples are
added to the dataset on disk (``data/round_<k>.npz``, bit-packed maps) and
the network is trained for ``epochs`` passes over all of it (cross-entropy
over the map's cells). This is the issue's "aggregated on-disk DAgger
dataset trained for several epochs per round": the workers' frames cost
nothing to the learner, and a sample is reused ``epochs`` times per round.

``--method reinforce --init-from DIR`` fine-tunes a trained network instead: every round's
episodes are driven by goals sampled from it, and it takes a policy-gradient step towards the
goals of the episodes that succeeded (REINFORCE with a per-node mean baseline, each goal's
probability ratio clipped as in PPO so that a round cannot drive it to zero), or with ``--credit
progress`` towards the goals whose walk brought the agent geodesically nearer, kept near the
teacher by a cross-entropy term; this optimises the hop success itself rather than agreement
with a teacher the network cannot always read.

Written under ``--out``: ``goal.pt`` (the network, after each round),
``state.pt`` (network, optimiser, round: what resuming reads),
``progress.csv`` (per round: samples, the driving policy's success, loss and
accuracy), TensorBoard events, ``training_curves.png``.
"""

from __future__ import annotations

import argparse
import concurrent.futures
import csv
import dataclasses
import io
import math
import multiprocessing
import os
import pathlib
import sys
import time

import numpy as np
import torch
import torch.nn.functional as F

from leaps_mj.environment import goal_teacher, map_navigation, mapping, roomnav
from leaps_mj.learning import checkpoints, goal_policy, nets, training_env
from leaps_mj.learning import credit as credit_lib
from leaps_mj.learning import trainer as trainer_lib
from leaps_mj.world import dataset as dataset_lib
from leaps_mj.world import files
from leaps_mj.world import rooms


#: The learner's arithmetic (``GoalTrainConfig.precision``): float32, or bfloat16 CPU autocast.
PRECISIONS = ("fp32", "bf16")

#: The goal teachers by name (``GoalTrainConfig.teacher``).
TEACHERS = {"geodesic": goal_teacher.TeacherGoals, "observable": goal_teacher.ObservableTeacherGoals,
            "observable-furniture": goal_teacher.FurnitureTeacherGoals, "sensed": goal_teacher.SensedTeacherGoals,
            "gated": goal_teacher.GatedTeacherGoals}


@dataclasses.dataclass(frozen=True)
class GoalTrainConfig:
    """A map-goal training run.

    Attributes:
      dataset: House dataset (its ``train`` split).
      num_houses: Train on the first this many houses of the split (0: all), sharded over the workers.
      width, height: Frame resolution the maps are built from.
      workers: Worker processes collecting episodes.
      rounds: DAgger rounds.
      episodes: Episodes collected per round (all workers together).
      beta: Probability that the teacher's goals drive an episode after round 0.
      epochs: Passes over the whole dataset after each round.
      max_updates: At most this many minibatch updates per round (0: no cap). Capped, a round's
        passes stop early and train on a uniform random part of the dataset, so the learner's time
        per round stops growing with the dataset (uncapped, a run's learning time grows with the
        square of its rounds).
      batch: Minibatch size.
      lr: Adam learning rate.
      mirror: Also train on each map mirrored left-right with its goal mirrored (a symmetry of the
        task: every sample counts twice; each minibatch mirrors a random half).
      rotate: Also train on each map turned by a random multiple of 90° about the agent with its goal
        turned alike: which cell a map's walls, doors and objects make the goal hardly depends on
        which way the agent faces (with ``mirror``, the 8 symmetries of the square).
      label_sigma: Spread (cells) of the goal label: 0 trains on the teacher's one cell, above 0 on a
        Gaussian over the cells around it (neighbouring cells lead the same way).
      context: Whether the network also reads the coarse 16 m window around the agent
        (:meth:`leaps_mj.environment.mapping.EgoMapper.context`).
      cues: Whether the maps mark the target's cues (:data:`leaps_mj.environment.mapping.CUES`).
      semantic: Whether the maps mark every room type's see-objects in channels of their own
        (:data:`leaps_mj.environment.mapping.SEMANTIC`).
      room_bits: Whether the network also reads the observation's room-type bits (the semantic-augmented
        policy μ_s, ``python -m leaps_mj.evaluate --agent aug``; stored with each sample).
      potential: Whether the network also has the potential head (``nets.GoalNetConfig.potential``),
        trained by regression on the teacher's potential labels
        (:meth:`leaps_mj.environment.goal_teacher.TeacherGoals.labels`, stored with each sample).
      potential_coef: Weight of the potential's loss (metres) beside the goal cross-entropy.
      potential_quantile: Which quantile of the potential, over what the map leaves open, the head
        predicts: 0.5 trains it with the smooth-L1 loss (a robust central value), any other value in
        (0, 1) with that quantile's pinball loss (below 0.5: optimistic — a way that *may* lead on
        scores low even where another may too; see :func:`potential_loss`).
      decoder: The potential head's decoder (``nets.GoalNetConfig.decoder``: ``linear`` or ``conv``).
      goal_head: How the goal logits are read off the features (``nets.GoalNetConfig.goal_head``:
        ``linear``, each cell's own weights, or ``conv``, one convolution scoring every cell alike).
      goals: What the network's goals are picked from (``nets.GoalNetConfig.goals``: ``logits`` or
        ``potential``), when it drives the training episodes and as the sub-policy.
      teacher: Whose path the goal labels follow (:data:`TEACHERS`): ``geodesic``
        (:class:`leaps_mj.environment.goal_teacher.TeacherGoals`, straight to the target), ``observable``
        (:class:`leaps_mj.environment.goal_teacher.ObservableTeacherGoals`, exploring until the target's
        room has been seen), ``observable-furniture`` (the same, rooms seen by their furniture only),
        ``sensed`` (that, exploring only the doors the agent has mapped) or ``gated``
        (:class:`leaps_mj.environment.goal_teacher.GatedTeacherGoals`: the geodesic teacher's door once
        the agent has mapped it, looking around and frontiers until then).
      method: ``dagger`` (the rounds above) or ``reinforce``: each round the network's goals, sampled
        at ``temperature``, drive every episode, and the network takes a policy-gradient step on
        its goal choices (advantage: the episode's success minus the round's mean success for its
        node) plus ``bc_coef`` times the cross-entropy to the teacher's goals on the round's states;
        no dataset is aggregated. For fine-tuning a DAgger network (``init_from``).
      clip: With ``reinforce``, the PPO clip range of the probability ratio of each chosen goal to its
        probability before the round's update (0: the plain policy gradient, unbounded; session 25 saw
        it blow up within one round of 1,200 episodes at lr 1e-3: the log-probability of failed goals is pushed
        towards minus infinity).
      credit: How ``reinforce`` credits a goal choice (:func:`leaps_mj.learning.credit.choice_advantages`):
        ``episode``, the episode's success shared by all of its choices, or ``progress``, the geodesic metres
        towards the target walked while the choice and those after it drove, discounted by ``credit_gamma`` per
        choice (a privileged signal used only in training, so each choice is credited for what it bought).
      credit_gamma: Discount per later goal choice of the ``progress`` credit.
      init_from: A ``goal.pt`` (or folder holding one) whose weights a new run starts from ("": none).
      init_data: Other DAgger runs' folders, separated by commas, whose aggregated datasets (their
        ``data/round_*.npz``) a new run starts from ("": none): its learner trains on those samples and its
        own rounds', so a continuation adds to what the other runs learned from instead of replacing it.
      temperature: Softmax temperature of the goals sampled by ``reinforce`` (below 1: nearer the
        argmax the sub-policy acts with).
      bc_coef: Weight of the cross-entropy to the teacher's goals in ``reinforce``.
      commit_turns: Whether the collecting drivers finish a turn before choosing the next goal
        (:class:`leaps_mj.environment.map_navigation.GoalDriver`); the shipped network was collected
        without (False), the sub-policy acts with it.
      horizon: Steps of a training episode.
      max_start_doors: Starts at most this many doors from a room of the target.
      max_start_distance: Starts at most this many metres (geodesic) from it.
      min_start_distance: Starts at least this many metres (geodesic) from it (0: as near as the room allows).
      far_fraction: The fraction of the training episodes ``min_start_distance`` applies to; the others start
        as near as the room allows (a mixture of near and far starts).
      precision: Arithmetic of the learner's forward and backward passes: ``fp32``, or ``bf16`` (CPU
        autocast: convolutions and matrix products in bfloat16, which CPUs with AMX or AVX-512 BF16 run
        1.6-2x faster; weights, optimizer state, losses and the acting networks stay float32).
      seed: Seed of every random draw of the run.
    """

    dataset: str = dataset_lib.CANONICAL
    num_houses: int = 64
    width: int = 40
    height: int = 30
    workers: int = 2
    rounds: int = 8
    episodes: int = 240
    beta: float = 0.25
    epochs: int = 3
    max_updates: int = 0
    batch: int = 256
    lr: float = 1e-3
    mirror: bool = False
    rotate: bool = False
    label_sigma: float = 0.0
    context: bool = False
    cues: bool = False
    semantic: bool = False
    room_bits: bool = False
    potential: bool = False
    potential_coef: float = 1.0
    potential_quantile: float = 0.5
    decoder: str = "linear"
    goals: str = "logits"
    goal_head: str = "linear"
    teacher: str = "geodesic"
    method: str = "dagger"
    init_from: str = ""
    init_data: str = ""
    temperature: float = 0.5
    bc_coef: float = 0.5
    clip: float = 0.2
    credit: str = "episode"
    credit_gamma: float = 0.7
    commit_turns: bool = False
    horizon: int = 60
    max_start_doors: int = 2
    max_start_distance: float = 13.0
    min_start_distance: float = 0.0
    far_fraction: float = 1.0
    precision: str = "fp32"
    seed: int = 0

    @property
    def net_config(self) -> nets.GoalNetConfig:
        """The architecture of the network this run trains."""
        return nets.GoalNetConfig(width=self.width, height=self.height, context=self.context, cues=self.cues,
                                 semantic=self.semantic, room_bits=self.room_bits, potential=self.potential,
                                 decoder=self.decoder, goals=self.goals, goal_head=self.goal_head)

    @property
    def init_runs(self) -> tuple[str, ...]:
        """The folders ``init_data`` names, in order."""
        return tuple(run for run in self.init_data.split(",") if run)

    def __post_init__(self):
        for name in ("workers", "rounds", "episodes", "epochs", "batch", "horizon", "max_start_doors",
                     "width", "height"):
            value = getattr(self, name)
            if isinstance(value, bool) or not isinstance(value, int) or value < 1:
                raise ValueError(f"{name} {value!r}: expected a positive integer")
        for name in ("num_houses", "max_updates"):
            value = getattr(self, name)
            if isinstance(value, bool) or not isinstance(value, int) or value < 0:
                raise ValueError(f"{name} {value!r}: expected an integer >= 0")
        if self.teacher not in TEACHERS:
            raise ValueError(f"teacher {self.teacher!r}: expected one of {sorted(TEACHERS)}")
        if self.goal_head not in nets.GOAL_HEADS:
            raise ValueError(f"goal_head {self.goal_head!r}: expected 'linear' or 'conv'")
        if self.precision not in PRECISIONS:
            raise ValueError(f"precision {self.precision!r}: expected 'fp32' or 'bf16'")
        if self.method not in ("dagger", "reinforce"):
            raise ValueError(f"method {self.method!r}: expected 'dagger' or 'reinforce'")
        if self.credit not in credit_lib.CREDITS:
            raise ValueError(f"credit {self.credit!r}: expected one of {credit_lib.CREDITS}")
        if not 0.0 <= self.min_start_distance < self.max_start_distance:
            raise ValueError(f"min_start_distance {self.min_start_distance!r}: expected a value in "
                             f"[0, max_start_distance={self.max_start_distance!r})")
        if not 0.0 < self.far_fraction <= 1.0:
            raise ValueError(f"far_fraction {self.far_fraction!r}: expected a value in (0, 1]")
        if not 0.0 <= self.credit_gamma <= 1.0:
            raise ValueError(f"credit_gamma {self.credit_gamma!r}: expected a value in [0, 1]")
        if not 0.0 <= self.beta <= 1.0:
            raise ValueError(f"beta {self.beta!r}: expected a value in [0, 1]")
        if not self.label_sigma >= 0:
            raise ValueError(f"label_sigma {self.label_sigma!r}: expected a number >= 0")
        if not 0.0 <= self.clip < 1.0:
            raise ValueError(f"clip {self.clip!r}: expected a value in [0, 1)")
        for name in ("bc_coef", "potential_coef"):
            if not getattr(self, name) >= 0:
                raise ValueError(f"{name} {getattr(self, name)!r}: expected a number >= 0")
        if not 0.0 < self.potential_quantile < 1.0:
            raise ValueError(f"potential_quantile {self.potential_quantile!r}: expected a value in (0, 1)")
        if self.potential and self.method == "reinforce":
            raise ValueError("potential True with method 'reinforce': policy-gradient fine-tuning trains the goal "
                             "logits only; expected potential False")
        for run in self.init_runs:
            if not saved_rounds(run):
                raise ValueError(f"init_data {run!r}: expected a goal run's folder holding data/round_*.npz")
        for name in ("lr", "max_start_distance", "temperature"):
            if not getattr(self, name) > 0:
                raise ValueError(f"{name} {getattr(self, name)!r}: expected a positive number")


def saved_rounds(run: str | os.PathLike) -> list[pathlib.Path]:
    """The DAgger rounds a goal run's folder holds on disk (``data/round_*.npz``), in round order."""
    return sorted(pathlib.Path(run, "data").glob("round_*.npz"))


PRESETS = {
    # Seconds: for tests.
    "tiny": GoalTrainConfig(num_houses=4, width=24, height=18, workers=1, rounds=2, episodes=2, epochs=1,
                            batch=16, horizon=12),
    # The shipped network (session 19, arm CHb30 of docs/training.md): 30 rounds of 240 hop-like episodes on the
    # 2 cores (about 290 k samples; 2.2 h with --threads 2), mirrored maps, goal labels spread over σ = 1 cell,
    # the coarse 16 m context window, one channel per room type's see-objects, the convolutional goal head and a
    # bfloat16 learner. Session 12's SClos: --rounds 12 --goal-head linear --precision fp32.
    "cpu": GoalTrainConfig(rounds=30, mirror=True, label_sigma=1.0, context=True, semantic=True, goal_head="conv",
                           precision="bf16"),
}


def collect(config: GoalTrainConfig, houses_dir: str, seed: int, episodes: int, beta: float,
            state_dict: dict | None, temperature: float | None = None) -> dict[str, np.ndarray]:
    """Runs ``episodes`` training episodes in one process and returns their labelled samples.

    Args:
      config: The run's configuration.
      houses_dir: This worker's shard of the training houses.
      seed: Seed of the environment, the teacher and the goal coins.
      episodes: Episodes to run.
      beta: Probability that the teacher's goals drive an episode (the network's otherwise).
      state_dict: The network's weights (None: the teacher drives every episode).
      temperature: The network's goals are sampled from its softmax at this temperature (None: its argmax).

    Returns:
      ``maps`` (N, packed bytes) uint8 bit-packed egocentric maps, ``bits``
      (N, NUM_ROOM_TYPES) uint8 room-type bits, ``node`` (N,) and ``label`` (N,) ints, ``choice`` (N,) the goal chosen at each
      step (-1 where none was), ``episode`` (N,) each step's episode index; with ``config.potential``,
      ``potential`` (N, WINDOW, WINDOW) int8 the potential labels;
      ``distance`` (N,) the geodesic metres to the target before each step's action;
      ``success`` (E,) and ``teacher`` (E,) bools: whether each episode
      succeeded and whether the teacher drove it, ``final_distance`` (E,) its last geodesic distance.
    """
    torch.set_num_threads(1)
    rng = np.random.default_rng(seed)
    net = None
    if state_dict is not None:
        net = nets.GoalNet(config.net_config)
        net.load_state_dict(state_dict)
        net.eval()
    def make(env_seed: int, min_start_distance: float):
        env = roomnav.load(seed=env_seed, houses_dir=houses_dir, width=config.width, height=config.height,
                           horizon=config.horizon, targets=rooms.GRAPH_NODES, max_start_doors=config.max_start_doors,
                           max_start_distance=config.max_start_distance, min_start_distance=min_start_distance)
        return env, TEACHERS[config.teacher](env, env_seed)

    # envs[0] draws starts at least min_start_distance away (every episode's, when far_fraction is 1); with
    # far_fraction < 1, envs[1] draws the other episodes' starts as near as the room allows.
    envs = [make(seed, config.min_start_distance)] + ([make(seed + 1, 0.0)] if config.far_fraction < 1 else [])
    drivers: dict[str, map_navigation.GoalDriver] = {}
    maps, bits, nodes, labels, potentials, choices, episode_of, success, driven = [], [], [], [], [], [], [], [], []
    distance, final_distance = [], []
    try:
        for episode in range(episodes):
            env, teacher = envs[0] if len(envs) == 1 or rng.random() < config.far_fraction else envs[1]
            ts = env.reset()
            target = env.task.episode.target
            driver = drivers.setdefault(target, map_navigation.GoalDriver(
                target, config.width, config.height, commit_turns=config.commit_turns, context=config.context,
                cues=config.cues, semantic=config.semantic))
            driver.reset(int(rng.integers(2 ** 31)))
            by_teacher = net is None or rng.random() < beta
            while not ts.last():
                window = driver.observe(ts.observation)
                label, potential = teacher.labels(driver.mapper, driver.pose, config.potential)
                if config.potential:
                    potentials.append(potential)
                maps.append(np.packbits(window))
                bits.append(np.asarray(ts.observation["semantic"], np.uint8))
                nodes.append(driver.node)
                labels.append(label)
                episode_of.append(episode)
                distance.append(env.task.distance)
                choice = -1
                if driver.needs_goal():
                    if by_teacher:
                        choice = label
                    elif temperature is None:
                        choice = goal_policy.choose_goal(net, driver, window, bits[-1] if config.room_bits else None)
                    else:
                        with torch.no_grad():
                            logits = net(torch.as_tensor(window[None]), torch.tensor([driver.node]),
                                         torch.as_tensor(bits[-1][None]) if config.room_bits else None)[0]
                        p = torch.softmax(logits.double() / temperature, 0).numpy()
                        choice = int(rng.choice(len(p), p=p / p.sum()))
                    driver.set_goal(choice)
                choices.append(choice)
                ts = env.step(driver.act())
            success.append(bool(env.task.success))
            final_distance.append(env.task.distance)
            driven.append(by_teacher)
    finally:
        for env, _ in envs:
            env.close()
    samples = {"maps": np.asarray(maps, np.uint8), "bits": np.asarray(bits, np.uint8).reshape(-1, rooms.NUM_ROOM_TYPES),
               "node": np.asarray(nodes, np.int64),
               "label": np.asarray(labels, np.int64), "choice": np.asarray(choices, np.int64),
               "episode": np.asarray(episode_of, np.int64), "success": np.asarray(success, bool),
               "teacher": np.asarray(driven, bool), "distance": np.asarray(distance, np.float32),
               "final_distance": np.asarray(final_distance, np.float32)}
    if config.potential:
        samples["potential"] = np.asarray(potentials, np.int8).reshape(-1, mapping.WINDOW, mapping.WINDOW)
    return samples


def _bits(config: GoalTrainConfig, samples: dict[str, np.ndarray], idx: np.ndarray) -> torch.Tensor | None:
    """The room-type bits of samples ``idx`` as the network's input where it reads them (None otherwise)."""
    return torch.as_tensor(samples["bits"][idx]) if config.room_bits else None


def goal_loss(logits: torch.Tensor, labels: torch.Tensor, sigma: float) -> torch.Tensor:
    """Cross-entropy of goal logits (B, WINDOW ** 2) to the teacher's cells (B,), spread over a Gaussian
    of ``sigma`` cells around each (plain cross-entropy at 0)."""
    if sigma == 0:
        return F.cross_entropy(logits, labels)
    cells = torch.arange(mapping.WINDOW, dtype=torch.float32)
    rows, cols = (labels // mapping.WINDOW).float(), (labels % mapping.WINDOW).float()
    d2 = (cells[None, :, None] - rows[:, None, None]) ** 2 + (cells[None, None, :] - cols[:, None, None]) ** 2
    target = torch.softmax(-d2.reshape(len(labels), -1) / (2 * sigma ** 2), dim=1)
    return -(target * F.log_softmax(logits, dim=1)).sum(1).mean()


def potential_loss(predicted: torch.Tensor, labels: torch.Tensor, quantile: float) -> torch.Tensor:
    """Loss of predicted potentials against their labels (both metres, same shape): smooth L1 at
    ``quantile`` 0.5, else the pinball loss whose minimiser is that quantile of the labels."""
    if quantile == 0.5:
        return F.smooth_l1_loss(predicted, labels)
    error = labels - predicted
    return torch.maximum(quantile * error, (quantile - 1.0) * error).mean()


def mirror(maps: torch.Tensor, labels: torch.Tensor, which: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor]:
    """Maps (B, C, S, S) and goal cells (B,) with the rows ``which`` (bool, B) mirrored left-right."""
    maps = torch.where(which[:, None, None, None], maps.flip(-1), maps)
    flipped = labels // mapping.WINDOW * mapping.WINDOW + (mapping.WINDOW - 1 - labels % mapping.WINDOW)
    return maps, torch.where(which, flipped, labels)


def rotate(maps: torch.Tensor, labels: torch.Tensor, turns: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor]:
    """Maps (B, C, S, S) and goal cells (B,) each turned counter-clockwise by ``turns`` (B,) quarter turns."""
    size = mapping.WINDOW
    rows, cols = labels // size, labels % size
    out_maps, out_labels = maps.clone(), labels.clone()
    for k in (1, 2, 3):
        which = turns == k
        if which.any():
            out_maps[which] = torch.rot90(maps[which], k, dims=(-2, -1))
            r, c = rows[which], cols[which]
            for _ in range(k):  # one counter-clockwise quarter turn: (r, c) -> (S - 1 - c, r)
                r, c = size - 1 - c, r
            out_labels[which] = r * size + c
    return out_maps, out_labels


def unpack_maps(maps: np.ndarray, channels: int) -> torch.Tensor:
    """Bit-packed maps of the on-disk dataset (N, bytes) back to (N, channels, WINDOW, WINDOW) uint8 tensors."""
    shape = (channels, mapping.WINDOW, mapping.WINDOW)
    bits = np.unpackbits(maps, axis=1, count=int(np.prod(shape)))
    return torch.as_tensor(bits.reshape(-1, *shape))


class GoalTrainer(trainer_lib.Trainer):
    """DAgger in rounds for the map-goal network (one iteration = one round)."""

    unit = "round"
    loss_keys = frozenset({"loss", "pg_loss", "potential_loss", "accuracy"})
    growable = frozenset({"rounds"})  # nothing is scheduled over the rounds: a finished run can go on

    def __init__(self, config: GoalTrainConfig, out: str | os.PathLike, progress: bool = True):
        super().__init__(config, out, config.rounds, progress=progress, desc="goal rounds")
        torch.manual_seed(config.seed)
        self.model = nets.GoalNet(config.net_config)
        self.optimizer = torch.optim.Adam(self.model.parameters(), lr=config.lr)
        self.data_dir = self.out / "data"
        self._pool = None
        self._data: dict[str, np.ndarray] | None = None  # the aggregated dataset, once read

    def session(self):
        self._pool = concurrent.futures.ProcessPoolExecutor(
            self.config.workers, mp_context=multiprocessing.get_context("spawn"))
        return self._pool

    def _collect(self) -> dict[str, np.ndarray]:
        c = self.config
        shards = training_env.training_houses(c.dataset, None, c.num_houses, c.workers, self.out, name="goal")
        reinforce = c.method == "reinforce"
        weights = None if self.iteration == 0 and not reinforce else {
            k: v.clone() for k, v in self.model.state_dict().items()}
        beta = 0.0 if reinforce else 1.0 if self.iteration == 0 else c.beta
        temperature = c.temperature if reinforce else None
        counts = [c.episodes // c.workers + (w < c.episodes % c.workers) for w in range(c.workers)]
        futures = [self._pool.submit(collect, c, str(shard), c.seed + 1000 * self.iteration + w, n, beta, weights,
                                     temperature)
                   for w, (shard, n) in enumerate(zip(shards, counts)) if n]
        parts = [f.result() for f in futures]
        first = np.cumsum([0] + [len(p["success"]) for p in parts[:-1]])
        for part, offset in zip(parts, first):
            part["episode"] = part["episode"] + offset  # episode indices over all workers
        return {k: np.concatenate([p[k] for p in parts]) for k in parts[0]}

    def warm_start(self, path: str | os.PathLike) -> None:
        """Starts a new run from the weights of a ``goal.pt`` (or a folder holding one).

        Raises:
          ValueError: naming the file, if it holds another network than this run's.
        """
        path = pathlib.Path(path)
        model, _ = goal_policy.load_goal_net(path / goal_policy.GOAL if path.is_dir() else path)
        if model.config != self.model.config:
            raise ValueError(f"init_from {path}: holds a network {model.config}, "
                             f"expected this run's {self.model.config}")
        self.model.load_state_dict(model.state_dict())

    def _dataset(self, fresh: dict[str, np.ndarray]) -> dict[str, np.ndarray]:
        """Every round's samples so far (``init_data``'s first), this round's (``fresh``) last: earlier rounds
        are read from disk once (after a resume), then kept in memory."""
        keys = (("maps", "node", "label") + (("bits",) if self.config.room_bits else ())
                + (("potential",) if self.config.potential else ()))
        if self._data is None:
            initial = [path for run in self.config.init_runs for path in saved_rounds(run)]
            parts = [np.load(path) for path in initial] + [
                np.load(self.data_dir / f"round_{k:03d}.npz") for k in range(self.iteration)]
            parts = [{k: part[k] for k in keys if k in part} for part in parts]
            for path, part in zip(initial, parts):
                if any(k not in part or part[k].shape[1:] != fresh[k].shape[1:] for k in keys):
                    raise ValueError(f"init_data {path}: holds samples { {k: v.shape[1:] for k, v in part.items()} }, "
                                     f"expected this run's { {k: fresh[k].shape[1:] for k in keys} }")
            self._data = {k: np.concatenate([p[k] for p in parts]) if parts else fresh[k][:0] for k in keys}
        self._data = {k: np.concatenate([self._data[k], fresh[k]]) for k in keys}
        return self._data

    def _autocast(self) -> torch.autocast:
        """The learner's forward passes in the run's ``precision`` (the backward follows their dtypes)."""
        return torch.autocast("cpu", dtype=torch.bfloat16, enabled=self.config.precision == "bf16")

    def iterate(self) -> dict:
        return self._reinforce() if self.config.method == "reinforce" else self._dagger()

    def _reinforce(self) -> dict:
        """One round of policy-gradient fine-tuning on the goals the network sampled (see ``method``)."""
        c = self.config
        t0 = time.perf_counter()
        fresh = self._collect()
        collect_seconds = time.perf_counter() - t0
        won = fresh["success"].astype(np.float64)
        advantage = torch.as_tensor(credit_lib.choice_advantages(fresh, c.credit, c.credit_gamma), dtype=torch.float32)
        rng = np.random.default_rng(c.seed + self.iteration)
        batches = [np.sort(order[start:start + c.batch])
                   for order in [rng.permutation(len(fresh["label"]))] for start in range(0, len(order), c.batch)]
        old_logp = torch.zeros(len(fresh["label"]))  # each chosen goal's log-probability under the sampling weights
        if c.clip:  # only the clipped objective reads it: the plain gradient skips this pass over the round
            with torch.no_grad():
                for idx in batches:
                    old_logp[idx] = self._choice_logp(fresh, idx)[0]
        self.model.train()
        pg_losses, bc_losses = [], []
        for idx in batches:
            logp, logits = self._choice_logp(fresh, idx)
            bc = goal_loss(logits, torch.as_tensor(fresh["label"][idx]), c.label_sigma)
            chose = torch.as_tensor(fresh["choice"][idx] >= 0)
            pg = torch.zeros(())
            if chose.any():
                gain, logp = advantage[idx][chose], logp[chose]
                if c.clip:
                    ratio = torch.exp(logp - old_logp[idx][chose])
                    pg = -torch.minimum(ratio * gain, ratio.clamp(1 - c.clip, 1 + c.clip) * gain).mean()
                else:
                    pg = -(gain * logp).mean()
            loss = pg + c.bc_coef * bc
            self.optimizer.zero_grad()
            loss.backward()
            self.optimizer.step()
            pg_losses.append(pg.item())
            bc_losses.append(bc.item())
        self.model.eval()
        return {"samples": len(fresh["label"]), "fresh_samples": len(fresh["label"]),
                "teacher_success": float("nan"), "learner_success": float(won.mean()),
                "loss": float(np.mean(bc_losses)), "pg_loss": float(np.mean(pg_losses)), "potential_loss": float("nan"),
                "accuracy": float("nan"), "collect_seconds": collect_seconds,
                "train_seconds": time.perf_counter() - t0 - collect_seconds}

    def _choice_logp(self, samples: dict[str, np.ndarray], idx: np.ndarray) -> tuple[torch.Tensor, torch.Tensor]:
        """The log-probability at ``temperature`` of each sample's chosen goal (0 where none was chosen),
        and the goal logits, for samples ``idx``."""
        c = self.config
        with self._autocast():
            logits = self.model(unpack_maps(samples["maps"][idx], self.model.config.input_channels),
                                torch.as_tensor(samples["node"][idx]), _bits(c, samples, idx)).float()
        choice = torch.as_tensor(samples["choice"][idx])
        logp = F.log_softmax(logits / c.temperature, dim=1).gather(1, choice.clamp(min=0)[:, None])[:, 0]
        return torch.where(choice >= 0, logp, torch.zeros(())), logits

    def _dagger(self) -> dict:
        """One DAgger round: collect, add to the dataset on disk, train ``epochs`` passes over all of it."""
        c = self.config
        t0 = time.perf_counter()
        fresh = self._collect()
        collect_seconds = time.perf_counter() - t0
        self.data_dir.mkdir(parents=True, exist_ok=True)
        buffer = io.BytesIO()
        np.savez_compressed(buffer, **fresh)
        files.write_atomic(self.data_dir / f"round_{self.iteration:03d}.npz", buffer.getvalue())
        data = self._dataset(fresh)
        rng = np.random.default_rng(c.seed + self.iteration)
        self.model.train()
        losses, potential_losses, correct, seen = [], [], 0, 0
        batches = [start for _ in range(c.epochs) for start in range(0, len(data["label"]), c.batch)]
        if c.max_updates:
            batches = batches[:c.max_updates]
        for start in batches:
            if start == 0:
                order = rng.permutation(len(data["label"]))
            idx = np.sort(order[start:start + c.batch])
            channels = self.model.config.input_channels
            maps = unpack_maps(data["maps"][idx], channels)
            if c.potential:  # turned with the map: its last channel
                potential_labels = torch.as_tensor(data["potential"][idx], dtype=torch.float32)[:, None]
                maps = torch.cat([maps.float(), potential_labels], 1)
            labels = torch.as_tensor(data["label"][idx])
            if c.mirror:
                maps, labels = mirror(maps, labels, torch.as_tensor(rng.random(len(idx)) < 0.5))
            if c.rotate:
                maps, labels = rotate(maps, labels, torch.as_tensor(rng.integers(0, 4, len(idx))))
            with self._autocast():
                logits, potential = self.model.heads(maps[:, :channels], torch.as_tensor(data["node"][idx]),
                                                     _bits(c, data, idx))
            logits = logits.float()
            potential = None if potential is None else potential.float()
            loss = goal_loss(logits, labels, c.label_sigma)
            if c.potential:
                regression = potential_loss(potential, maps[:, channels].flatten(1) * mapping.CELL,
                                            c.potential_quantile)
                loss = loss + c.potential_coef * regression
                potential_losses.append(regression.item())
            self.optimizer.zero_grad()
            loss.backward()
            self.optimizer.step()
            losses.append(loss.item())
            correct += int((logits.argmax(1) == labels).sum())
            seen += len(idx)
        self.model.eval()
        learner = ~fresh["teacher"]
        return {"samples": len(data["label"]), "fresh_samples": len(fresh["label"]),
                "teacher_success": float(fresh["success"][~learner].mean()) if (~learner).any() else float("nan"),
                "learner_success": float(fresh["success"][learner].mean()) if learner.any() else float("nan"),
                "loss": float(np.mean(losses[-max(1, len(losses) // c.epochs):])), "accuracy": correct / seen,
                "potential_loss": (float(np.mean(potential_losses[-max(1, len(potential_losses) // c.epochs):]))
                                   if potential_losses else float("nan")),
                "collect_seconds": collect_seconds, "train_seconds": time.perf_counter() - t0 - collect_seconds}

    def postfix(self, row: dict) -> dict[str, str]:
        return {"learner": f"{row['learner_success']:.2f}", "acc": f"{row['accuracy']:.2f}"}

    def publish(self, extra: dict) -> None:
        checkpoints.save_checkpoint(self.out / goal_policy.GOAL, self.model, self.model.config, extra)


def plot_curves(progress: pathlib.Path, out: pathlib.Path) -> pathlib.Path:
    """Success of the episodes each round's goals drove (teacher, learner) and the imitation accuracy."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    with open(progress) as f:
        rows = list(csv.DictReader(f))
    rounds = [int(r["round"]) for r in rows]
    fig, ax = plt.subplots(figsize=(6, 4))
    for key, label in (("teacher_success", "episodes driven by the teacher's goals"),
                       ("learner_success", "episodes driven by the network's goals"),
                       ("accuracy", "goal-cell accuracy (training)")):
        values = [float(r[key]) if r[key] not in ("", "nan") else math.nan for r in rows]
        ax.plot(rounds, values, marker="o", label=label)
    ax.set_xlabel("DAgger round")
    ax.set_ylim(0, 1)
    ax.set_title("map-goal sub-policy training")
    ax.grid(alpha=0.3)
    ax.legend(fontsize=8)
    fig.tight_layout()
    fig.savefig(out, dpi=120)
    plt.close(fig)
    return out


def build_parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(prog="python -m leaps_mj.train goal", description=__doc__.split("\n\n")[0],
                                     formatter_class=argparse.ArgumentDefaultsHelpFormatter)
    parser.add_argument("--preset", choices=sorted(PRESETS), default="cpu", help="base configuration")
    parser.add_argument("--out", default="runs/goal", help="output folder (resumed if it holds a run)")
    parser.add_argument("--threads", type=int, default=1, help="torch CPU threads of the learner")
    parser.add_argument("--stop-after", type=int, default=None,
                        help="stop after this many more rounds (checkpointed; rerun resumes)")
    parser.add_argument("--no-progress", action="store_true", help="no progress bar")
    trainer_lib.add_config_arguments(parser, GoalTrainConfig)
    return parser


def main(argv=None) -> int:
    args = build_parser().parse_args(argv)
    config = dataclasses.replace(PRESETS[args.preset], **trainer_lib.config_overrides(args, GoalTrainConfig))
    if args.threads < 1:
        raise ValueError(f"--threads {args.threads}: expected a positive integer")
    if args.stop_after is not None and args.stop_after < 1:
        raise ValueError(f"--stop-after {args.stop_after}: expected a positive integer")
    torch.set_num_threads(args.threads)
    trainer = GoalTrainer(config, args.out, progress=not args.no_progress)
    if not trainer.resume(config.width, config.height) and config.init_from:
        trainer.warm_start(config.init_from)
    trainer.train(args.stop_after)
    if trainer.finished:
        print(f"wrote {trainer.out / goal_policy.GOAL} and {plot_curves(trainer.out / 'progress.csv', trainer.out / 'training_curves.png')}")
    else:
        print(f"stopped after round {trainer.iteration} of {config.rounds}; rerun the same command to resume")
    return 0


if __name__ == "__main__":
    sys.exit(main())
