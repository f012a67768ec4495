"""The configuration of a sub-policy training run, and its presets (tiny, cpu, paper).

Apart from the trainer so that its environments, losses and evaluation can
take the configuration without importing the training loop.
"""

from __future__ import annotations

import dataclasses
import math

from leaps_mj.environment import expert, looking_expert, observable_expert
from leaps_mj.learning import nets
from leaps_mj.world import dataset as dataset_lib

METHODS = ("a2c", "dagger", "dagger+a2c")
#: DAgger teachers by name: the map-reading geodesic expert, or the one acting only on what was observed.
TEACHERS = {"geodesic": expert.GeodesicExpert, "geodesic-scan": expert.ScanningGeodesicExpert,
            "geodesic-look": looking_expert.LookingGeodesicExpert,
            "observable": observable_expert.ObservableExpert}


@dataclasses.dataclass(frozen=True)
class TrainConfig:
    """Everything that defines a sub-policy training run (one per preset).

    Attributes:
      dataset: House dataset name or folder (its ``train`` split is used).
      num_houses: Train on the first this many houses of the split that have
        a room of the target type (0: all of them), sharded over the workers.
      width, height: Frame resolution of the environment and the network.
      conv_channels, kernel, hidden, lstm, seg_embed: Network widths
        (:class:`leaps_mj.learning.nets.PolicyConfig`).
      use_semantic: Train the semantic-augmented policy μ_s: the network
        also reads the room-type bits and the target one-hot.
      shared: Train one network for all the run's targets (it reads the
        graph node's one-hot; episodes draw their target among the run's
        targets present in the house, over all the training houses) instead
        of one network per target. Written as ``shared.pt``.
      prev_action: The network also reads the action taken at the previous
        step (:class:`leaps_mj.learning.nets.PolicyConfig` ``prev_action``).
      map_input: The network also reads the egocentric top-down map the
        agent builds from its frames and pose
        (:class:`leaps_mj.environment.mapping.EgoMapper`; the environments
        add it to the observation as ``egomap``).
      aux_coef: Weight of the auxiliary losses (0: no auxiliary heads): the
        rooms each vertical strip of the frame shows, the room-type bits
        where the agent stands and the geodesic distance to the target,
        labels the simulator gives for free and that only training reads.
      method: "a2c", "dagger" or "dagger+a2c".
      init_from: A policy checkpoint (``<target>.pt`` or ``shared.pt`` of
        another run, same network), or a folder of them (each target starts
        from its own), whose weights start the run instead of a random
        initialisation: to continue a shipped set with another recipe, or
        fine-tune a DAgger-trained network with A2C. Empty: none.
      teacher: Whose actions label the DAgger samples (a key of
        :data:`TEACHERS`): "geodesic" (reads the map, so some of its choices
        cannot be known from the frames), "geodesic-scan" (the same, but
        turning left whenever the way is out of view,
        :class:`leaps_mj.environment.expert.ScanningGeodesicExpert`), "geodesic-look"
        (the same, but first looking around each room until the target is
        seen, :class:`leaps_mj.environment.looking_expert.LookingGeodesicExpert`) or
        "observable" (chooses from the
        rooms seen and the doors passed so far,
        :class:`leaps_mj.environment.observable_expert.ObservableExpert`).
      total_steps: Environment steps per target (all environments together).
      dagger_fraction: Share of the iterations spent on DAgger in "dagger+a2c".
      beta_fraction: Share of the DAgger iterations over which β, the
        probability that the expert takes a step of a mixed environment,
        decays linearly from 1 to ``beta_min``.
      beta_min: Final β of the DAgger phase. Above 0, mixed environments keep
        following the expert with the learner's deviations (DART-like): the
        learner's own early rollouts mostly turn on the spot, and labels from
        them alone teach it to keep turning.
      learner_envs: Environments always driven by the learner alone.
      replay: Extra DAgger updates per iteration, each on one unroll drawn
        from the aggregated dataset.
      buffer_steps: Samples kept in the aggregated dataset (oldest dropped).
      num_envs: Environments (worker processes) stepped together.
      t_max: Unroll length of one update.
      gamma: Discount of the n-step returns.
      lr: Adam learning rate.
      weight_decay: Adam weight decay.
      entropy: Entropy bonus coefficient (A2C).
      bc_coef: Weight of an imitation loss kept in the A2C phase: the
        cross-entropy to the teacher's labels of the learner's own states,
        anchoring the policy gradient near the imitated policy (a policy
        fine-tuned by A2C alone from a DAgger start collapsed within 30 k
        samples to turning on the spot). 0: pure A2C, no labels.
      value_coef: Value-loss coefficient.
      logits_l2: Coefficient of the mean squared logits penalty.
      max_grad_norm: Gradient clipping norm.
      normalize_advantages: Normalise advantages over each unroll (A2C).
      horizon: Steps of a training episode.
      start_distance: Initial bound on the start's geodesic distance (metres).
      distance_step: Metres added to the bound every ``curriculum_iterations``.
      curriculum_iterations: Iterations per curriculum stage.
      max_distance: Largest bound the curriculum reaches (metres).
      max_start_doors: If above 0, starts lie at most this many doors from a
        room of the target (the neighbouring-room hops LEAPS asks of its
        sub-policies); 0 bounds starts by distance only.
      checkpoint_every: Iterations between checkpoints.
      eval_episodes: Episodes of the final evaluation, per split.
      eval_horizon: Steps of an evaluation episode.
      seed: Seed of every random draw of the run.
    """

    dataset: str = dataset_lib.CANONICAL
    num_houses: int = 0
    width: int = 120
    height: int = 90
    conv_channels: tuple[int, ...] = (64, 64, 128, 128)
    kernel: int = 5
    hidden: int = 256
    lstm: int = 256
    seg_embed: int = 8
    use_semantic: bool = False
    shared: bool = False
    prev_action: bool = False
    map_input: bool = False
    aux_coef: float = 0.0
    method: str = "a2c"
    init_from: str = ""
    teacher: str = "geodesic"
    total_steps: int = 20_000_000
    dagger_fraction: float = 0.7
    beta_fraction: float = 0.5
    beta_min: float = 0.0
    learner_envs: int = 1
    replay: int = 2
    buffer_steps: int = 50_000
    num_envs: int = 64
    t_max: int = 30
    gamma: float = 0.97
    lr: float = 1e-3
    weight_decay: float = 1e-5
    entropy: float = 0.1
    bc_coef: float = 0.0
    value_coef: float = 0.5
    logits_l2: float = 0.01
    max_grad_norm: float = 1.0
    normalize_advantages: bool = True
    horizon: int = 60
    start_distance: float = 6.0
    distance_step: float = 3.0
    curriculum_iterations: int = 10_000
    max_distance: float = 30.0
    max_start_doors: int = 0
    checkpoint_every: int = 100
    eval_episodes: int = 20
    eval_horizon: int = 100
    seed: int = 0

    def __post_init__(self):
        object.__setattr__(self, "conv_channels", tuple(self.conv_channels))
        if self.method not in METHODS:
            raise ValueError(f"method {self.method!r}: expected one of {list(METHODS)}")
        if self.teacher not in TEACHERS:
            raise ValueError(f"teacher {self.teacher!r}: expected one of {list(TEACHERS)}")
        for name in ("total_steps", "num_envs", "t_max", "horizon", "curriculum_iterations",
                     "checkpoint_every", "eval_episodes", "eval_horizon", "buffer_steps"):
            value = getattr(self, name)
            if isinstance(value, bool) or not isinstance(value, int) or value < 1:
                raise ValueError(f"{name} {value!r}: expected a positive integer")
        for name in ("num_houses", "replay", "seed", "max_start_doors"):
            value = getattr(self, name)
            if isinstance(value, bool) or not isinstance(value, int) or value < 0:
                raise ValueError(f"{name} {value!r}: expected an integer >= 0")
        for name in ("dagger_fraction", "beta_fraction", "beta_min", "gamma"):
            if not 0.0 <= getattr(self, name) <= 1.0:
                raise ValueError(f"{name} {getattr(self, name)!r}: expected a value in [0, 1]")
        for name in ("lr", "start_distance", "max_distance", "max_grad_norm"):
            if not getattr(self, name) > 0:
                raise ValueError(f"{name} {getattr(self, name)!r}: expected a positive number")
        for name in ("weight_decay", "entropy", "value_coef", "logits_l2", "distance_step", "aux_coef",
                     "bc_coef"):
            if not getattr(self, name) >= 0:
                raise ValueError(f"{name} {getattr(self, name)!r}: expected a number >= 0")
        if self.shared and self.use_semantic:
            raise ValueError("shared and use_semantic: expected at most one (μ_s is trained per target)")
        if not isinstance(self.learner_envs, int) or not 0 <= self.learner_envs <= self.num_envs:
            raise ValueError(f"learner_envs {self.learner_envs!r}: expected an integer in [0, num_envs]")
        self.policy_config()  # validates the network fields

    def policy_config(self) -> nets.PolicyConfig:
        """The network architecture of this run."""
        return nets.PolicyConfig(width=self.width, height=self.height, conv_channels=self.conv_channels,
                                 kernel=self.kernel, hidden=self.hidden, lstm=self.lstm, seg_embed=self.seg_embed,
                                 use_semantic=self.use_semantic, target_input=self.shared,
                                 prev_action=self.prev_action, aux=self.aux_coef > 0,
                                 map_input=self.map_input)

    @property
    def labelled(self) -> bool:
        """Whether the environments label their states with the teacher's actions (DAgger, or A2C with ``bc_coef``)."""
        return self.method != "a2c" or self.bc_coef > 0

    @property
    def batch(self) -> int:
        """Samples per iteration."""
        return self.num_envs * self.t_max

    @property
    def iterations(self) -> int:
        """Iterations of the whole run."""
        return math.ceil(self.total_steps / self.batch)

    @property
    def dagger_iterations(self) -> int:
        """Iterations of the DAgger phase (the first ones)."""
        return {"a2c": 0, "dagger": self.iterations,
                "dagger+a2c": round(self.dagger_fraction * self.iterations)}[self.method]

    def start_distance_at(self, iteration: int) -> float:
        """The curriculum's bound on start distances (metres) at an iteration."""
        stage = iteration // self.curriculum_iterations
        return min(self.max_distance, self.start_distance + self.distance_step * stage)

    def beta_at(self, iteration: int) -> float:
        """Probability that the expert takes a step of a mixed environment at an iteration."""
        if iteration >= self.dagger_iterations:
            return 0.0
        decay = max(1, round(self.beta_fraction * self.dagger_iterations))
        return max(self.beta_min, 1.0 - iteration / decay)


PRESETS = {
    # Seconds: for tests and smoke runs.
    "tiny": TrainConfig(
        num_houses=4, width=24, height=18, conv_channels=(8, 8), hidden=16, lstm=16,
        method="dagger+a2c", total_steps=96, num_envs=2, t_max=8, replay=1, buffer_steps=64,
        horizon=20, start_distance=3.0, curriculum_iterations=2, checkpoint_every=2,
        eval_episodes=2, eval_horizon=10),
    # All 9 targets in about 50 minutes on 2 shared CPU cores: 40x30 frames, a
    # narrow net, 32 houses with the target (4 per worker), DAgger only.
    "cpu": TrainConfig(
        num_houses=32, width=40, height=30, conv_channels=(16, 32, 32, 32), hidden=128, lstm=64,
        method="dagger", total_steps=108_000, beta_min=0.5, learner_envs=2, replay=3, num_envs=8,
        start_distance=4.0, curriculum_iterations=90, max_distance=13.0, checkpoint_every=10),
    # The hop recipe (issue 13): one network for the 9 graph nodes over all the training
    # houses, auxiliary losses, the release's task distribution (starts within 2 doors,
    # 60-step episodes), 16 environments in 2 worker processes.
    "hop": TrainConfig(
        width=40, height=30, conv_channels=(16, 32, 32, 32), hidden=128, lstm=128, shared=True, aux_coef=0.5,
        method="dagger", total_steps=960_000, beta_min=0.5, learner_envs=4, replay=2, buffer_steps=96_000,
        num_envs=16, horizon=60, start_distance=20.0, distance_step=0.0, max_distance=20.0, max_start_doors=2,
        checkpoint_every=10),
    # The paper's setting, for a GPU or a cluster (not run on the CPU machine).
    "paper": TrainConfig(),
}
