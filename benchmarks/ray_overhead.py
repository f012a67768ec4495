"""Ray overhead: evaluation episodes/s, local backend vs Ray actors, measured side by side.

Prints one table; every row runs the same jobs (the first ``--episodes`` of
the split's fixed set in chunks of ``--chunk``, ``--agent`` at ``--horizon``)
through :func:`leaps_mj.evaluation.harness.chunk_results`, the backend-dependent
part of ``harness.run``, in one run of this script, so a busy shared machine
affects all rows alike:

* ``local, 1 worker``: in this process (the default).
* ``local, 2 workers``: the spawned process pool.
* ``ray, 1 actor`` / ``ray, 2 actors``: Ray actors on a local instance of
  ``--cpus`` CPUs, started once before the rows (its start-up time is printed
  apart; on a cluster it is paid once per session, not per run).

Columns: the whole run's wall time and episodes/s, start-up included (each
worker builds its environment and agents once), as a user's run sees them;
the time to the first finished chunk (start-up and one chunk); and the rate
after the first chunk of every worker, the rate a long run tends to. Every
row's results are checked to be the same rows.

    python benchmarks/ray_overhead.py [--dataset roomnav-v2] [--episodes 96] [--agent random] [--horizon 300]
"""

from __future__ import annotations

import argparse
import os
import time

import ray

import leaps_mj  # noqa: F401  (selects the GL backend before MuJoCo loads)
from leaps_mj.evaluation import backends, harness
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


def main() -> None:
    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--dataset", default=dataset_lib.CANONICAL)
    p.add_argument("--split", default="test")
    p.add_argument("--episodes", type=int, default=96)
    p.add_argument("--agent", default="random", choices=list(harness.AGENTS))
    p.add_argument("--horizon", type=int, default=300)
    p.add_argument("--chunk", type=int, default=4)
    p.add_argument("--cpus", type=int, default=os.cpu_count())
    args = p.parse_args()
    config = harness.EvalConfig(dataset=args.dataset, split=args.split, horizon=args.horizon)
    spec = harness.AGENTS[args.agent]
    jobs = [(spec, list(range(k, min(k + args.chunk, args.episodes)))) for k in range(0, args.episodes, args.chunk)]
    rows = [("local", 1), ("local", 2), ("ray", 1), ("ray", 2)]
    t0 = time.perf_counter()
    ray.init(num_cpus=args.cpus, include_dashboard=False, log_to_driver=False)
    startup = time.perf_counter() - t0
    runs = [timed_run(backends.Backend(name, workers), jobs, config) for name, workers in rows]
    ray.shutdown()
    if any(r != runs[0][1] for _, r in runs):
        raise SystemExit("the backends' rows differ")
    print(f"{args.episodes} episodes of `{args.agent}` at H = {args.horizon} on {args.dataset}/{args.split}, "
          f"chunks of {args.chunk}; ray.init({args.cpus} CPUs) took {startup:.1f} s; load average "
          f"{os.getloadavg()[0]:.1f} on {os.cpu_count()} cores; the same rows from every backend\n")
    print("| backend | workers | wall (s) | episodes/s | first chunk (s) | episodes/s after each worker's first chunk "
          "| vs local, 1 worker |")
    print("|---|---:|---:|---:|---:|---:|---:|")
    base = None
    for (name, workers), (stamps, _) in zip(rows, runs):
        steady = (args.episodes - workers * args.chunk) / (stamps[-1] - stamps[workers - 1])
        base = base or steady
        print(f"| {name} | {workers} | {stamps[-1]:.1f} | {args.episodes / stamps[-1]:.2f} | {stamps[0]:.1f} | "
              f"{steady:.2f} | {steady / base:.2f}× |")


if __name__ == "__main__":
    main()
