"""Ray overhead: evaluation episodes/s and training samples/s, local backend vs Ray actors, side by side.

Prints up to two tables (``--tables``), each from rows run in one run of this
script, so a busy shared machine affects all rows alike. Ray runs on a local
instance of ``--cpus`` CPUs, started once before the rows (its start-up time
is printed apart; on a cluster it is paid once per session, not per run).

**Evaluation**: every row runs the same jobs (the first ``--episodes`` of
the split's fixed set in chunks of ``--chunk``, ``--agent`` at ``--horizon``)
through :func:`leaps_mj.evaluation.harness.chunk_results`, the
backend-dependent part of ``harness.run``:

* ``local, 1 worker``: in this process (the default).
* ``local, 2 workers``: the spawned process pool.
* ``ray, 1 actor`` / ``ray, 2 actors``: Ray actors.

Columns: the whole run's wall time and episodes/s, start-up included (each
worker builds its environment and agents once), as a user's run sees them;
the time to the first finished chunk (start-up and one chunk); and the rate
after the first chunk of every worker, the rate a long run tends to. Every
row's results are checked to be the same rows.

**Training**: ``--train-warmup`` + ``--train-iterations`` iterations of the
sub-policy trainer (``--train-preset``, target ``--train-target``) with its
rollouts on the local backend (``num_envs`` environments in one worker
process per core) and on 1 and 2 Ray rollout actors (the environments split
between them). Columns: the wall time from the trainer's construction to the
end (environments' or actors' start-up included), the first iteration
(start-up and house compilation), both of the round with the best rate, and
training samples/s over the iterations after the warm-up, in each round (the
learner's update included: it is the same in every row). Rounds alternate the
rows' order, so that a load that changes over time hits every row.

    python benchmarks/ray_overhead.py [--tables evaluation training] [--dataset roomnav-v2] [--episodes 96]
        [--agent random] [--horizon 300] [--train-preset cpu] [--train-iterations 6] [--train-repeats 2]
"""

from __future__ import annotations

import argparse
import dataclasses
import os
import tempfile
import time

import numpy as np
import ray

import leaps_mj  # noqa: F401  (selects the GL backend before MuJoCo loads)
from leaps_mj.evaluation import backends, harness
from leaps_mj.learning import policy_eval, train_policy
from leaps_mj.world import dataset as dataset_lib


def timed_run(where: backends.Backend, jobs: list, config: harness.EvalConfig) -> tuple[list[float], list]:
    """Seconds from the start to each finished chunk, and every row sorted by episode."""
    stamps, rows = [], []
    t0 = time.perf_counter()
    with harness.chunk_results(where, jobs, config) as results:
        for _, chunk_rows in results:
            stamps.append(time.perf_counter() - t0)
            rows += chunk_rows
    return stamps, sorted(rows, key=lambda r: r["episode"])


def evaluation_table(args: argparse.Namespace) -> None:
    """Runs the evaluation rows and prints their table."""
    config = harness.EvalConfig(dataset=args.dataset, split=args.split, horizon=args.horizon)
    spec = harness.AGENTS[args.agent]
    jobs = [(spec, list(range(k, min(k + args.chunk, args.episodes)))) for k in range(0, args.episodes, args.chunk)]
    rows = [("local", 1), ("local", 2), ("ray", 1), ("ray", 2)]
    runs = [timed_run(backends.Backend(name, workers), jobs, config) for name, workers in rows]
    if any(r != runs[0][1] for _, r in runs):
        raise SystemExit("the backends' rows differ")
    print(f"{args.episodes} episodes of `{args.agent}` at H = {args.horizon} on {args.dataset}/{args.split}, "
          f"chunks of {args.chunk}; load average {os.getloadavg()[0]:.1f} on {os.cpu_count()} cores; the same rows "
          "from every backend\n")
    print("| backend | workers | wall (s) | episodes/s | first chunk (s) | episodes/s after each worker's first chunk "
          "| vs local, 1 worker |")
    print("|---|---:|---:|---:|---:|---:|---:|")
    base = None
    for (name, workers), (stamps, _) in zip(rows, runs):
        steady = (args.episodes - workers * args.chunk) / (stamps[-1] - stamps[workers - 1])
        base = base or steady
        print(f"| {name} | {workers} | {stamps[-1]:.1f} | {args.episodes / stamps[-1]:.2f} | {stamps[0]:.1f} | "
              f"{steady:.2f} | {steady / base:.2f}× |")
    print()


def timed_training(config: train_policy.TrainConfig, target: str, warmup: int, backend: str,
                   workers: int | None) -> dict[str, float]:
    """Trains ``config`` (in a temporary folder) on a rollout backend; returns its wall times and samples/s."""
    with tempfile.TemporaryDirectory(prefix="ray_overhead_") as out:
        t0 = time.perf_counter()
        trainer = train_policy.Trainer(config, target, out, progress=False, backend=backend, num_workers=workers)
        trainer.train()
        wall = time.perf_counter() - t0
        sps = policy_eval.read_progress(f"{out}/{target}/progress.csv")["SPS"]
    return {"wall": wall, "first": config.batch / sps[0],
            "sps": config.batch * len(sps[warmup:]) / np.sum(config.batch / sps[warmup:])}


def training_table(args: argparse.Namespace) -> None:
    """Runs the training rows (``--train-repeats`` rounds, every other one in reverse order) and prints their table."""
    import torch

    torch.set_num_threads(1)  # the learner's threads, as `python -m leaps_mj.train policy` sets by default
    base = train_policy.PRESETS[args.train_preset]
    iterations = args.train_warmup + args.train_iterations
    config = dataclasses.replace(base, dataset=args.dataset, total_steps=iterations * base.batch,
                                 checkpoint_every=iterations)
    target = train_policy.SHARED if config.shared else args.train_target
    rows = [("local", None), ("ray", 1), ("ray", 2)]
    runs = {row: [] for row in rows}
    for round_ in range(args.train_repeats):
        for row in rows if round_ % 2 == 0 else rows[::-1]:
            runs[row].append(timed_training(config, target, args.train_warmup, *row))
    print(f"preset {args.train_preset} ({config.method}, {config.num_envs} environments x {config.t_max} steps = "
          f"{config.batch} samples per iteration, {config.width}x{config.height}) on {args.dataset}, target "
          f"{target}: {args.train_warmup} warm-up + {args.train_iterations} measured iterations, "
          f"{args.train_repeats} rounds (every other one in reverse order), 1 learner thread; load average "
          f"{os.getloadavg()[0]:.1f} on {os.cpu_count()} cores\n")
    print("| rollouts | workers | wall (s) | first iteration (s) | samples/s after warm-up, each round "
          "| best vs local |")
    print("|---|---:|---:|---:|---:|---:|")
    local_best = max(r["sps"] for r in runs[rows[0]])
    for (name, workers), results in runs.items():
        where = (f"{min(os.cpu_count(), config.num_envs)} processes" if workers is None
                 else f"{workers} actor{'s' * (workers > 1)}")
        best = max(results, key=lambda r: r["sps"])
        rates = " / ".join(f"{r['sps']:.0f}" for r in results)
        print(f"| {name} | {where} | {best['wall']:.1f} | {best['first']:.1f} | {rates} | "
              f"{best['sps'] / local_best:.2f}× |")


def main() -> None:
    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--tables", nargs="+", choices=("evaluation", "training"), default=["evaluation", "training"])
    p.add_argument("--dataset", default=dataset_lib.CANONICAL)
    p.add_argument("--split", default="test")
    p.add_argument("--episodes", type=int, default=96)
    p.add_argument("--agent", default="random", choices=list(harness.AGENTS))
    p.add_argument("--horizon", type=int, default=300)
    p.add_argument("--chunk", type=int, default=4)
    p.add_argument("--train-preset", default="cpu", choices=sorted(train_policy.PRESETS))
    p.add_argument("--train-target", default="kitchen", help="target of a per-target preset")
    p.add_argument("--train-iterations", type=int, default=6, help="measured training iterations per row")
    p.add_argument("--train-warmup", type=int, default=2, help="training iterations not counted (house compilation)")
    p.add_argument("--train-repeats", type=int, default=2, help="rounds of the training rows")
    p.add_argument("--cpus", type=int, default=os.cpu_count())
    args = p.parse_args()
    if min(args.train_iterations, args.train_warmup, args.train_repeats) < 1:
        raise SystemExit(f"--train-iterations {args.train_iterations}, --train-warmup {args.train_warmup}, "
                         f"--train-repeats {args.train_repeats}: expected positive integers")
    t0 = time.perf_counter()
    ray.init(num_cpus=args.cpus, include_dashboard=False, log_to_driver=False)
    print(f"ray.init({args.cpus} CPUs) took {time.perf_counter() - t0:.1f} s\n")
    try:
        if "evaluation" in args.tables:
            evaluation_table(args)
        if "training" in args.tables:
            training_table(args)
    finally:
        ray.shutdown()


if __name__ == "__main__":
    main()
