"""Trains the HRL baseline's LSTM controller with A2C over options.

``python -m leaps_mj.train controller --preset tiny|cpu|paper --out DIR [--subpolicy auto|local|learned]
[--policy-dir DIR] [--backend local|ray [--ray-address ADDR] [--num-workers N]]``

The controller (:class:`leaps_mj.learning.nets.ControllerNet`, LSTM 50) acts in the
option-level problem of :class:`leaps_mj.learning.baselines.ControllerAgent`: each
decision picks a sub-target, whose sub-policy then runs for up to
``option_steps`` steps. Episodes are sampled from the training houses (any
target, any start, ``horizon`` steps). Rewards, from the original release:
``-option_cost`` per decision and ``+success_reward`` on success; returns are
discounted per decision with γ = 0.99 and end at success or the horizon.
A2C: the agent samples its choices; after every ``batch_episodes`` episodes
the loss ``-log π(a) (R - V) + value_coef (R - V)² / 2 - entropy H(π)`` over
all their decisions is minimised by one Adam step (lr 1e-3, gradient norm
clipped at ``max_grad_norm``).

Sub-policies (``--subpolicy``): ``learned`` = ``leaps_mj.learning.policies.load_default()``,
or with ``--policy-dir`` the sub-policies of that folder (per-target μ(θ) or the map-goal
network, :func:`leaps_mj.learning.policy_folder.load`); the environment then renders at their
resolution. ``local`` =
:class:`leaps_mj.planning.agents.LocalExpertPolicy`, ``auto`` = learned when the
shipped checkpoints load, else local. The choice is stored in the
checkpoint.

Files under ``DIR``: ``controller.pt`` (latest weights, loadable by
:func:`leaps_mj.learning.baselines.load_controller`; with the final validation result
once done), ``state.pt`` (resumable state), ``progress.csv`` (one row per
update), TensorBoard events. Re-running the same command resumes from the
last update (episode sampling continues from a fresh seeded stream, so a
resumed run is not bit-identical to an uninterrupted one); a different
configuration is refused.

Backends (``--backend``, a run option, not part of the configuration, so a
run may resume on the other): ``local`` plays each update's episodes one
after another in this process; ``ray`` plays them on Ray actors
(:mod:`leaps_mj.learning.ray_controller`, docs/ray.md), the same episodes
(house, target, start) as ``local`` but with per-episode sampling seeds.
"""

from __future__ import annotations

import argparse
import contextlib
import dataclasses
import json
import os
import sys
import time
from typing import Sequence

import numpy as np
import torch
import tqdm

from leaps_mj.environment import episodes, roomnav
from leaps_mj.learning import backend_options, baselines, checkpoints, nets
from leaps_mj.learning import trainer as trainer_lib
from leaps_mj.planning import agents
from leaps_mj.world import dataset as dataset_lib
from leaps_mj.world import rooms

SUBPOLICIES = ("auto", "local", "learned")


@dataclasses.dataclass(frozen=True)
class TrainConfig:
    """A controller training run (one per preset).

    Attributes:
      dataset: House dataset name or folder (train split; valid for the final check).
      subpolicy: "local" or "learned" ("auto" is resolved before a run starts).
      policy_dir: With ``subpolicy="learned"``, the folder of sub-policy checkpoints (None: the shipped μ(θ)).
      width, height: Environment resolution (the learned sub-policies' own).
      horizon: Steps of a training episode.
      option_steps: N, the longest option.
      lstm: Controller LSTM units.
      episodes: Training episodes in all.
      batch_episodes: Episodes per update.
      gamma: Discount per decision.
      entropy: Entropy bonus coefficient.
      value_coef: Value-loss coefficient.
      lr: Adam learning rate.
      max_grad_norm: Gradient clipping norm.
      option_cost: Reward -option_cost per decision.
      success_reward: Reward on success.
      eval_episodes: Fixed validation episodes of the final check (stratified by plan length).
      eval_horizon: Their horizon.
      seed: Seed of the episodes, the initialisation and the sampling.
    """

    dataset: str = dataset_lib.CANONICAL
    subpolicy: str = "local"
    policy_dir: str | None = None
    width: int = 40
    height: int = 30
    horizon: int = 300
    option_steps: int = 30
    lstm: int = 50
    episodes: int = 1200
    batch_episodes: int = 8
    gamma: float = 0.99
    entropy: float = 0.01
    value_coef: float = 0.5
    lr: float = 1e-3
    max_grad_norm: float = 1.0
    option_cost: float = 0.1
    success_reward: float = 2.0
    eval_episodes: int = 50
    eval_horizon: int = 300
    seed: int = 0

    def __post_init__(self):
        if self.subpolicy not in ("local", "learned"):
            raise ValueError(f"subpolicy {self.subpolicy!r}: expected 'local' or 'learned'")
        if self.policy_dir is not None and self.subpolicy != "learned":
            raise ValueError(f"policy_dir {self.policy_dir!r} needs subpolicy 'learned', not {self.subpolicy!r}")
        for name in ("horizon", "option_steps", "lstm", "episodes", "batch_episodes", "eval_episodes",
                     "eval_horizon"):
            value = getattr(self, name)
            if isinstance(value, bool) or not isinstance(value, int) or value < 1:
                raise ValueError(f"{name} {value!r}: expected a positive integer")
        if not 0.0 <= self.gamma <= 1.0:
            raise ValueError(f"gamma {self.gamma!r}: expected a value in [0, 1]")
        for name in ("lr", "max_grad_norm"):
            if not getattr(self, name) > 0:
                raise ValueError(f"{name} {getattr(self, name)!r}: expected a positive number")
        for name in ("entropy", "value_coef", "option_cost", "success_reward"):
            if not getattr(self, name) >= 0:
                raise ValueError(f"{name} {getattr(self, name)!r}: expected a number >= 0")

    @property
    def updates(self) -> int:
        return -(-self.episodes // self.batch_episodes)


PRESETS = {
    # Seconds: tests and smoke runs.
    "tiny": TrainConfig(horizon=40, option_steps=10, episodes=4, batch_episodes=2, eval_episodes=2,
                        eval_horizon=40),
    # About 45 minutes on 2 shared CPU cores with the learned sub-policies. The
    # paper's lr 1e-3 leaves the controller uniform (entropy ln 8) after this
    # few updates (1200 episodes in batches of 8: 150 updates); 10x the rate
    # in batches of 4 learns.
    "cpu": TrainConfig(lr=1e-2, episodes=10_000, batch_episodes=4),
    # The paper's learning rate, more episodes, its longest horizon.
    "paper": TrainConfig(horizon=1000, episodes=20_000, batch_episodes=16, eval_episodes=500, eval_horizon=1000),
}


def resolve_subpolicy(choice: str) -> str:
    """"auto" -> "learned" when the shipped sub-policies load, else "local" (saying why on stderr)."""
    if choice not in SUBPOLICIES:
        raise ValueError(f"subpolicy {choice!r}: expected one of {list(SUBPOLICIES)}")
    if choice != "auto":
        return choice
    from leaps_mj.learning import policies

    try:
        policies.load_default()
    except ValueError as e:
        print(f"controller: using the local-expert sub-policy ({e})", file=sys.stderr)
        return "local"
    return "learned"


def make_subpolicy(config: TrainConfig, env, seed: int):
    """The sub-policy of a run: the learned ones (shipped, or ``config.policy_dir``'s) or the local expert of ``env``."""
    if config.subpolicy == "learned":
        from leaps_mj.learning import policy_folder

        return policy_folder.load(config.policy_dir, seed=seed)
    return agents.LocalExpertPolicy(env, seed=seed)


def discounted_returns(rewards: np.ndarray, gamma: float) -> np.ndarray:
    """Returns of one episode's decisions, ending with the episode (no bootstrap)."""
    out = np.zeros(len(rewards), dtype=np.float64)
    following = 0.0
    for t in reversed(range(len(rewards))):
        following = rewards[t] + gamma * following
        out[t] = following
    return out


def run_training_episode(env, agent: baselines.ControllerAgent, config: TrainConfig) -> dict:
    """Runs a sampled episode; returns its decisions' inputs, choices, rewards and the outcome."""
    ts = env.reset()
    agent.reset(env.episode.target)
    while not ts.last():
        ts = env.step(agent.step(ts))
    success = bool(env.task.success)
    rewards = np.full(len(agent.decisions), -config.option_cost)
    rewards[-1] += config.success_reward * success
    return {"inputs": np.stack([d.inputs for d in agent.decisions]),
            "choices": np.array([d.subtarget for d in agent.decisions], dtype=np.int64),
            "rewards": rewards, "success": success, "steps": env.task.steps}


def target_of(episode: dict) -> int:
    """The target room type of a recorded episode (its one-hot block in the first input)."""
    k = rooms.NUM_ROOM_TYPES
    return int(episode["inputs"][0, 2 * k:3 * k].argmax())


def a2c_loss(net: nets.ControllerNet, batch: list[dict], config: TrainConfig) -> tuple[torch.Tensor, dict]:
    """The A2C loss over the decisions of a batch of episodes (LSTM unrolled per episode from zero state)."""
    lengths = [len(ep["choices"]) for ep in batch]
    T, B = max(lengths), len(batch)
    x = torch.zeros(T, B, 4 * rooms.NUM_ROOM_TYPES)
    choices = torch.zeros(T, B, dtype=torch.long)
    returns = torch.zeros(T, B)
    valid = torch.zeros(T, B)
    for b, ep in enumerate(batch):
        n = lengths[b]
        x[:n, b] = torch.as_tensor(ep["inputs"])
        choices[:n, b] = torch.as_tensor(ep["choices"])
        returns[:n, b] = torch.as_tensor(discounted_returns(ep["rewards"], config.gamma), dtype=torch.float32)
        valid[:n, b] = 1.0
    state = net.initial_state(B)
    logits, values = [], []
    for t in range(T):
        lt, vt, state = net(x[t], state)
        logits.append(lt)
        values.append(vt)
    dist = torch.distributions.Categorical(logits=torch.stack(logits))
    values = torch.stack(values)
    advantages = returns - values.detach()
    n = valid.sum()
    policy_loss = -(dist.log_prob(choices) * advantages * valid).sum() / n
    value_loss = 0.5 * (((returns - values) ** 2) * valid).sum() / n
    entropy = (dist.entropy() * valid).sum() / n
    loss = policy_loss + config.value_coef * value_loss - config.entropy * entropy
    return loss, {"policy_loss": policy_loss.item(), "value_loss": value_loss.item(), "entropy": entropy.item()}


class Trainer(trainer_lib.Trainer):
    """Trains (or resumes) a controller run in ``out``; see the module docstring.

    Args:
      config: The run's configuration.
      out: Its folder.
      progress: Show progress bars.
      backend: Where the training episodes run, "local" or "ray".
      num_workers: Ray actors (default: one per cluster CPU, at most ``batch_episodes``).
      ray_address: The Ray cluster's address (default: a local instance).
    """

    unit = "update"
    loss_keys = frozenset({"policy_loss", "value_loss", "entropy"})
    # Nothing is scheduled over the episodes (constant learning rate and entropy weight; each
    # update's seeds depend on its index only): a finished run can go on, e.g. over a new sub-policy.
    growable = frozenset({"episodes"})

    def __init__(self, config: TrainConfig, out: str | os.PathLike, progress: bool = True, backend: str = "local",
                 num_workers: int | None = None, ray_address: str | None = None):
        # Each Ray actor plays at least one episode per update.
        backend_options.check_backend(backend, num_workers, ray_address, config.batch_episodes, "batch_episodes")
        self.backend, self.num_workers, self.ray_address = backend, num_workers, ray_address
        super().__init__(config, out, config.updates, progress=progress, desc="controller updates")
        self.policy_path = self.out / "controller.pt"
        torch.manual_seed(config.seed)
        self.net = self.model = nets.ControllerNet(nets.ControllerConfig(lstm=config.lstm))
        self.optimizer = torch.optim.Adam(self.net.parameters(), lr=config.lr)
        self.history: list[dict] = []
        self.eval: dict | None = None
        self.resume()
        self.net.eval()

    @property
    def update(self) -> int:
        return self.iteration

    def state(self) -> dict:
        return {"option_steps": self.config.option_steps, "subpolicy": self.config.subpolicy,
                "history": self.history, "eval": self.eval}

    def load_state(self, extra: dict) -> None:
        self.history, self.eval = extra["history"], extra["eval"]

    def publish(self, extra: dict) -> None:
        checkpoints.save_checkpoint(self.policy_path, self.net, self.net.config, extra)

    def log_step(self, row: dict) -> int:
        return row["episodes"]

    def postfix(self, row: dict) -> dict[str, str]:
        return {"success": f"{row['success_rate']:.2f}", "decisions": f"{row['decisions']:.1f}"}

    def _seed(self, *keys: int) -> int:
        return int(np.random.SeedSequence([self.config.seed, *keys]).generate_state(1)[0])

    @contextlib.contextmanager
    def session(self):
        """The training environment (or the Ray actors) of one ``train`` call."""
        c = self.config
        if self.backend == "ray":
            from leaps_mj.learning import ray_controller

            with ray_controller.RayController(c, run_training_episode, make_subpolicy, self.update,
                                              self.num_workers, self.ray_address) as self._ray:
                yield
            return
        self._env = roomnav.load(c.dataset, "train", seed=self._seed(1, self.update), width=c.width,
                                 height=c.height, horizon=c.horizon, reward="sparse")
        try:
            yield
        finally:
            self._env.close()

    def play(self) -> list[dict]:
        """The records of this update's ``batch_episodes`` training episodes, played on the run's backend."""
        c = self.config
        if self.backend == "ray":
            return self._ray.play(self.net, self.update)
        # A fresh sub-policy per update: the local expert caches distance fields per house.
        sub = make_subpolicy(c, self._env, self._seed(2, self.update))
        agent = baselines.ControllerAgent(sub, self.net, c.option_steps, seed=self._seed(3, self.update))
        return [run_training_episode(self._env, agent, c) for _ in range(c.batch_episodes)]

    def iterate(self) -> dict:
        c = self.config
        t0 = time.perf_counter()
        batch = self.play()
        self.net.train()
        loss, scalars = a2c_loss(self.net, batch, c)
        self.optimizer.zero_grad()
        loss.backward()
        torch.nn.utils.clip_grad_norm_(self.net.parameters(), c.max_grad_norm)
        self.optimizer.step()
        self.net.eval()
        row = {"episodes": (self.update + 1) * c.batch_episodes,
               "success_rate": float(np.mean([ep["success"] for ep in batch])),
               "decisions": float(np.mean([len(ep["choices"]) for ep in batch])),
               "return": float(np.mean([discounted_returns(ep["rewards"], c.gamma)[0] for ep in batch])),
               "steps": float(np.mean([ep["steps"] for ep in batch])),
               "target_choices": float(np.mean(np.concatenate([ep["choices"] == target_of(ep) for ep in batch]))),
               **scalars, "seconds": time.perf_counter() - t0}
        self.history.append({"update": self.update + 1, **row})
        return row

    def validate(self) -> dict:
        """Success of the controller, and of the pure baseline with the same sub-policy, on fixed valid episodes."""
        c = self.config
        specs = episodes.load_split(c.dataset, "valid")
        per_length = max(1, c.eval_episodes // episodes.MAX_PLAN_LENGTH)
        indices = episodes.select_episodes(specs, per_length, c.eval_episodes, c.seed)
        env = roomnav.load(c.dataset, "valid", seed=c.seed, width=c.width, height=c.height,
                            horizon=c.eval_horizon, reward="sparse")
        results = {"controller": [], "pure": []}
        try:
            for i in tqdm.tqdm(indices, desc="controller validation", disable=not self.progress):
                seed = episodes.episode_seed(c.seed, i)
                for name, agent in (
                        ("controller", baselines.ControllerAgent(make_subpolicy(c, env, seed), self.net,
                                                                 c.option_steps, seed=seed)),
                        ("pure", agents.PureAgent(make_subpolicy(c, env, seed)))):
                    results[name].append(episodes.run_episode(env, agent, specs[i], c.eval_horizon)["success"])
        finally:
            env.close()
        return {"episodes": len(indices), "horizon": c.eval_horizon,
                **{f"{name}_success": float(np.mean(r)) for name, r in results.items()}}


def main(argv: Sequence[str] | None = None) -> int:
    parser = argparse.ArgumentParser(prog="python -m leaps_mj.train controller", description=__doc__.split("\n\n")[0],
                                     formatter_class=argparse.ArgumentDefaultsHelpFormatter)
    parser.add_argument("--preset", choices=sorted(PRESETS), default="cpu", help="base configuration")
    parser.add_argument("--out", default="runs/controller", help="output folder (resumed if it holds a run)")
    parser.add_argument("--subpolicy", choices=SUBPOLICIES, default="auto",
                        help="sub-policies: learned (shipped), local (local expert), auto (learned if shipped)")
    parser.add_argument("--policy-dir", default=None,
                        help="with --subpolicy learned: a folder of sub-policy checkpoints (<node>.pt, shared.pt or a "
                             "map-goal goal.pt) instead of the shipped ones")
    parser.add_argument("--threads", type=int, default=1, help="torch CPU threads")
    parser.add_argument("--stop-after", type=int, default=None,
                        help="stop after this many more updates (checkpointed; rerun resumes)")
    parser.add_argument("--no-progress", action="store_true", help="no progress bars")
    backend_options.add_backend_arguments(parser, "training episodes", "each playing batch_episodes / N episodes per "
                                   "update (default: one per cluster CPU, at most batch_episodes)")
    trainer_lib.add_config_arguments(parser, TrainConfig, skip=("subpolicy", "policy_dir"))
    args = parser.parse_args(argv)
    for name in ("threads", "stop_after"):
        if getattr(args, name) is not None and getattr(args, name) < 1:
            raise ValueError(f"--{name.replace('_', '-')} {getattr(args, name)}: expected a positive integer")
    overrides = trainer_lib.config_overrides(args, TrainConfig, skip=("subpolicy", "policy_dir"))
    subpolicy = "learned" if args.policy_dir is not None and args.subpolicy == "auto" else \
        resolve_subpolicy(args.subpolicy)
    if subpolicy == "learned":
        from leaps_mj.learning import policy_folder

        loaded = policy_folder.load(args.policy_dir)
        overrides.update(width=loaded.width, height=loaded.height)
    config = dataclasses.replace(PRESETS[args.preset], subpolicy=subpolicy, policy_dir=args.policy_dir,
                                 **overrides)
    torch.set_num_threads(args.threads)
    trainer = Trainer(config, args.out, progress=not args.no_progress, backend=args.backend,
                      num_workers=args.num_workers, ray_address=args.ray_address)
    trainer.train(args.stop_after)
    if not trainer.finished:
        print(f"stopped after update {trainer.update} of {config.updates}; rerun the same command to resume")
        return 0
    if trainer.eval is None:
        trainer.eval = trainer.validate()
        trainer.save()
    print(f"controller: {trainer.net.num_parameters():,} parameters (semantic model: 38); sub-policy "
          f"{config.subpolicy}; option steps {config.option_steps}")
    print(json.dumps(trainer.eval))
    return 0


if __name__ == "__main__":
    sys.exit(main())
