"""Ray overhead: evaluation episodes/s, local backend vs Ray actors, measured side by side.

Prints one table; every row runs the same episodes (the first ``--episodes``
of the split's fixed set, ``--agent`` at ``--horizon``) through
:func:`leaps_mj.evaluation.harness.run` into a fresh folder, in one run of
this script, so a busy shared machine affects all rows alike:

* ``local, 1 worker``: in this process (the default).
* ``local, 2 workers``: the spawned process pool.
* ``ray, 1 actor`` / ``ray, 2 actors``: Ray actors on a local instance of
  ``--cpus`` CPUs, started once before the rows (its start-up time is printed
  apart; on a cluster it is paid once per session, not per run).

Wall time includes starting the workers (each builds its environment and
agents once), as a user's run does. The CSVs of every row are checked to be
byte-identical.

    python benchmarks/ray_overhead.py [--dataset roomnav-v2] [--episodes 48] [--agent pure] [--horizon 300]
"""

from __future__ import annotations

import argparse
import os
import pathlib
import tempfile
import time

import ray

import leaps_mj  # noqa: F401  (selects the GL backend before MuJoCo loads)
from leaps_mj.evaluation import harness
from leaps_mj.world import dataset as dataset_lib


def main() -> None:
    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--dataset", default=dataset_lib.CANONICAL)
    p.add_argument("--split", default="test")
    p.add_argument("--episodes", type=int, default=48)
    p.add_argument("--agent", default="pure", choices=list(harness.AGENTS))
    p.add_argument("--horizon", type=int, default=300)
    p.add_argument("--chunk", type=int, default=4)
    p.add_argument("--cpus", type=int, default=os.cpu_count())
    args = p.parse_args()
    config = harness.EvalConfig(dataset=args.dataset, split=args.split, horizon=args.horizon)
    specs = [harness.AGENTS[args.agent]]
    rows = [("local", 1), ("local", 2), ("ray", 1), ("ray", 2)]
    t0 = time.perf_counter()
    ray.init(num_cpus=args.cpus, include_dashboard=False, log_to_driver=False)
    startup = time.perf_counter() - t0
    results = []
    with tempfile.TemporaryDirectory() as tmp:
        for backend, workers in rows:
            out = pathlib.Path(tmp) / f"{backend}{workers}"
            t0 = time.perf_counter()
            harness.run(config, specs, list(range(args.episodes)), out, workers=workers, chunk=args.chunk,
                        progress=False, backend=backend)
            results.append((time.perf_counter() - t0, harness.csv_path(out, args.agent).read_bytes()))
    ray.shutdown()
    if len({csv for _, csv in results}) != 1:
        raise SystemExit("the backends' CSVs differ")
    print(f"{args.episodes} episodes of `{args.agent}` at H = {args.horizon} on {args.dataset}/{args.split}, "
          f"chunks of {args.chunk}; ray.init({args.cpus} CPUs) took {startup:.1f} s; load average "
          f"{os.getloadavg()[0]:.1f} on {os.cpu_count()} cores; CSVs byte-identical\n")
    base = args.episodes / results[0][0]
    print("| backend | workers | wall (s) | episodes/s | vs local, 1 worker |")
    print("|---|---:|---:|---:|---:|")
    for (backend, workers), (wall, _) in zip(rows, results):
        rate = args.episodes / wall
        print(f"| {backend} | {workers} | {wall:.1f} | {rate:.2f} | {rate / base:.2f}× |")


if __name__ == "__main__":
    main()
