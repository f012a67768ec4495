"""Sub-policy training throughput, end to end, and where the time goes.

``python benchmarks/train_throughput.py [--presets cpu hop paper] [--iterations 4] [--num-envs N] [--device cpu]
[--goal-rounds 3] [--goal-precision fp32 bf16] [--goal-head linear]``

Runs a few iterations of :class:`leaps_mj.learning.train_policy.Trainer` per preset
(in a temporary folder; the first ``--warmup`` iterations, which compile the
houses, are not counted) and prints one row per preset: training samples per
second of wall-clock, and per 1000 samples the seconds spent

* in the learner process: acting forward passes, the environment step wait,
  the update's forward (unrolls through the CNN+LSTM) and its backward
  (gradients + Adam);
* in the environment workers (CPU-seconds, summed over workers that run in
  parallel): physics and collisions (``Task.before_step``), rendering and the
  success test (``Task.after_step``), and expert labelling (DAgger).

All of it is measured in the same run, from the trainer's own timers (the
``*_seconds`` columns of ``progress.csv``).

``--goal-rounds R`` (default 3; 0 skips it) also runs R rounds of the map-goal trainer's cpu preset
(:mod:`leaps_mj.learning.train_goal`: DAgger over an aggregated dataset on disk, several epochs a
round) in the same run and prints its own split: fresh samples per second of collection (2 worker
processes rendering, mapping and labelling), samples per second of the learner (each of its
minibatch passes over the dataset counts a sample once per epoch), and end to end both the fresh
samples and the trained samples per second of wall-clock. Its learner's share grows with the rounds
(each round trains over everything gathered so far), so the row says how many rounds it covers. One row
per ``--goal-precision`` (``GoalTrainConfig.precision``: the learner in float32 or bfloat16 autocast), run
one after the other in the same process on the same seeds, for ``--goal-head`` (``linear`` or ``conv``);
``--presets`` with no names skips the pixel presets. Each preset runs its own method:
cpu is DAgger (3 replayed updates per iteration), hop is DAgger with one
network shared by the 9 nodes and auxiliary losses (2 replayed updates),
paper is A2C (no expert). Each preset runs its own number of environments
except the paper preset, whose 64 are replaced by 8 (or ``--num-envs`` for
every preset) so that it fits this machine's memory; its network and
resolution are the paper's.
"""

from __future__ import annotations

import argparse
import dataclasses
import sys
import tempfile

import numpy as np

from leaps_mj.learning import nets, policy_eval, train_goal, train_policy
from leaps_mj.world import dataset

_COLUMNS = (
    ("act_forward_seconds", "act fwd"),
    ("env_wait_seconds", "env wait"),
    ("update_forward_seconds", "upd fwd"),
    ("update_backward_seconds", "upd bwd"),
    ("worker_render_seconds", "render*"),
    ("worker_physics_seconds", "physics*"),
    ("worker_expert_seconds", "expert*"),
)


def measure(preset: str, iterations: int, warmup: int, num_envs: int | None, device: str, dataset: str,
            target: str) -> dict:
    """Trains ``warmup + iterations`` iterations of a preset; returns the measured means."""
    base = train_policy.PRESETS[preset]
    num_envs = num_envs or (8 if preset == "paper" else base.num_envs)
    config = dataclasses.replace(base, dataset=dataset, num_envs=num_envs,
                                 learner_envs=min(base.learner_envs, num_envs),
                                 total_steps=(warmup + iterations) * num_envs * base.t_max,
                                 checkpoint_every=warmup + iterations)
    name = train_policy.SHARED if config.shared else target
    with tempfile.TemporaryDirectory(prefix="train_throughput_") as out:
        trainer = train_policy.Trainer(config, name, out, device=device, progress=False)
        trainer.train()
        log = policy_eval.read_progress(f"{out}/{name}/progress.csv")
    rows = slice(warmup, None)
    per_k = 1000 / config.batch
    return {
        "preset": preset, "method": config.method, "resolution": f"{config.width}x{config.height}",
        "params": nets.ActorCritic(config.policy_config()).num_parameters(), "envs": num_envs,
        "sps": config.batch * len(log["SPS"][rows]) / np.sum(config.batch / log["SPS"][rows]),
        **{key: float(np.nan_to_num(np.mean(log[key][rows]))) * per_k for key, _ in _COLUMNS},
    }


def measure_goal(rounds: int, dataset: str, precision: str, goal_head: str) -> dict:
    """Trains ``rounds`` rounds of the map-goal trainer's cpu preset; returns its samples per second."""
    config = dataclasses.replace(train_goal.PRESETS["cpu"], dataset=dataset, rounds=rounds, precision=precision,
                                 goal_head=goal_head)
    with tempfile.TemporaryDirectory(prefix="train_throughput_goal_") as out:
        train_goal.GoalTrainer(config, out, progress=False).train()
        log = policy_eval.read_progress(f"{out}/progress.csv")
    collect, learn = float(np.sum(log["collect_seconds"])), float(np.sum(log["train_seconds"]))
    fresh, trained = float(np.sum(log["fresh_samples"])), float(config.epochs * np.sum(log["samples"]))
    return {"precision": precision, "rounds": rounds, "fresh": fresh, "collect_sps": fresh / collect,
            "learner_sps": trained / learn, "fresh_sps": fresh / (collect + learn),
            "trained_sps": trained / (collect + learn), "learner_share": learn / (collect + learn)}


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--presets", nargs="*", default=["cpu", "hop", "paper"], choices=sorted(train_policy.PRESETS))
    parser.add_argument("--iterations", type=int, default=4, help="measured iterations per preset")
    parser.add_argument("--warmup", type=int, default=2, help="iterations not counted (house compilation)")
    parser.add_argument("--num-envs", type=int, default=None,
                        help="environments of every preset (default: the preset's own; 8 for paper)")
    parser.add_argument("--device", default="cpu", help="torch device of the learner")
    parser.add_argument("--threads", type=int, default=1, help="torch CPU threads of the learner")
    parser.add_argument("--dataset", default=dataset.CANONICAL)
    parser.add_argument("--target", default="kitchen", help="target of the per-target presets")
    parser.add_argument("--goal-rounds", type=int, default=3, help="rounds of the map-goal trainer (0: skip it)")
    parser.add_argument("--goal-precision", nargs="+", default=list(train_goal.PRECISIONS),
                        choices=train_goal.PRECISIONS,
                        help="learner precisions of the map-goal trainer, one row each")
    parser.add_argument("--goal-head", default="linear", choices=nets.GOAL_HEADS,
                        help="goal head of the map-goal network")
    args = parser.parse_args(argv)
    if args.iterations < 1 or args.warmup < 0 or (args.num_envs is not None and args.num_envs < 1) or args.threads < 1 \
            or args.goal_rounds < 0:
        raise ValueError(f"--iterations {args.iterations}, --warmup {args.warmup}, --num-envs {args.num_envs}, "
                         f"--threads {args.threads}, --goal-rounds {args.goal_rounds}: expected iterations, envs, "
                         f"threads >= 1 and warmup, goal rounds >= 0")
    import torch

    torch.set_num_threads(args.threads)
    results = [measure(p, args.iterations, args.warmup, args.num_envs, args.device, args.dataset, args.target)
               for p in args.presets]
    if results:
        head = f"{'preset':7} {'method':10} {'frames':7} {'params':>9} {'envs':>4} {'samples/s':>9} | "
        print(f"seconds per 1000 training samples (device {args.device}, {args.threads} learner thread(s); "
              "* = CPU-seconds in the env workers, summed over workers)")
        print(head + " ".join(f"{name:>8}" for _, name in _COLUMNS))
        for r in results:
            print(f"{r['preset']:7} {r['method']:10} {r['resolution']:7} {r['params']:9,d} {r['envs']:4d} "
                  f"{r['sps']:9.1f} | " + " ".join(f"{r[key]:8.2f}" for key, _ in _COLUMNS))
    if args.goal_rounds:
        rows = [measure_goal(args.goal_rounds, args.dataset, p, args.goal_head) for p in args.goal_precision]
        print(f"\nmap-goal trainer, cpu preset, {args.goal_head} goal head, {args.goal_rounds} rounds "
              f"({rows[0]['fresh']:,.0f} fresh samples), samples/s:")
        print(f"{'precision':>9} {'learner share':>13} {'collection (fresh)':>19} {'learner (trained)':>18} "
              f"{'end to end, fresh':>18} {'end to end, trained':>20}")
        for g in rows:
            print(f"{g['precision']:>9} {100 * g['learner_share']:12.0f}% {g['collect_sps']:19.1f} "
                  f"{g['learner_sps']:18.1f} {g['fresh_sps']:18.1f} {g['trained_sps']:20.1f}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
