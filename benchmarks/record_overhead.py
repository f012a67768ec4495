"""Recording overhead: env steps/s with and without an MCAP episode recorder.

Prints one table, every row measured in this run on the same episodes (the
same seeded random actions), interleaved over rounds (median reported) so a
noisy shared machine affects all rows alike:

* ``env only``: a RoomNav environment stepped with random actions.
* ``env + recorder``: the same, every step recorded (images, pose, semantic
  bits, action, reward) as a plain dm_env loop would.
* ``env + recorder + new belief each step``: also a 9x9 belief, a plan and
  a sub-target that change at every step, the worst case of what the LEAPS
  agent reports (it changes them at replans; unchanged ones are not
  re-published).

The last columns are the recorded file size per step and the slowdown.

    python benchmarks/record_overhead.py [--dataset roomnav-v2] [--episodes 4] [--steps 150] [--rounds 5]
"""

from __future__ import annotations

import argparse
import pathlib
import statistics
import tempfile
import time

import numpy as np

import leaps_mj
from leaps_mj.planning import semantic
from leaps_mj.records import recorder as record
from leaps_mj.world import dataset, rooms


def run(env, specs, actions, recorder=None, info=None) -> tuple[float, int]:
    """Runs the episodes, ``info(step)`` giving the agent's info; returns (seconds, steps)."""
    steps, t0 = 0, time.perf_counter()
    for spec, acts in zip(specs, actions):
        ts = env.reset_to(spec)
        if recorder is not None:
            recorder.begin(env, spec)
        for a in acts:
            if ts.last():
                break
            ts = env.step(int(a))
            steps += 1
            if recorder is not None:
                recorder.step(ts, int(a), info(steps) if info else None)
        if recorder is not None:
            recorder.end()
    return time.perf_counter() - t0, steps


def main(argv=None) -> int:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("--dataset", default=dataset.CANONICAL)
    p.add_argument("--split", default="test")
    p.add_argument("--episodes", type=int, default=4)
    p.add_argument("--steps", type=int, default=150, help="random actions per episode")
    p.add_argument("--rounds", type=int, default=5)
    p.add_argument("--width", type=int, default=120)
    p.add_argument("--height", type=int, default=90)
    p.add_argument("--seed", type=int, default=0)
    args = p.parse_args(argv)

    env = leaps_mj.load(args.dataset, args.split, seed=args.seed, width=args.width, height=args.height,
                        horizon=args.steps + 1, reward="sparse")
    specs = [env.sample_episode() for _ in range(args.episodes)]
    actions = np.random.default_rng(args.seed).integers(rooms.NUM_ACTIONS, size=(args.episodes, args.steps))
    posterior = semantic.SemanticModel.from_reference().posterior()

    def changing_belief(step):
        sub = rooms.GRAPH_NODES[step % len(rooms.GRAPH_NODES)]
        return {"subtarget": sub, "plan": [sub, "indoor"], "belief": posterior * (1 - 1e-4 * (step % 100))}

    run(env, specs, actions)  # compile every house once before timing
    rows = {"env only": None, "env + recorder": None, "env + recorder + new belief each step": changing_belief}
    rates = {name: [] for name in rows}
    sizes = {}
    with tempfile.TemporaryDirectory() as tmp:
        for r in range(args.rounds):
            for name, info in rows.items():
                out = pathlib.Path(tmp) / f"{r}_{len(sizes)}_{name.replace(' ', '')}"
                rec = None if name == "env only" else record.EpisodeRecorder(out, env)
                seconds, steps = run(env, specs, actions, rec, info)
                rates[name].append(steps / seconds)
                if rec is not None:
                    sizes[name] = sum(f.stat().st_size for f in out.glob("*.mcap")) / steps
    base = statistics.median(rates["env only"])
    print(f"{args.episodes} episodes x {args.steps} random actions, {args.width}x{args.height}, "
          f"{args.dataset}/{args.split}, median of {args.rounds} rounds\n")
    print(f"| {'condition':<38} | steps/s | ms/step | KiB/step | slowdown |")
    print(f"|{'-' * 40}|---------|---------|----------|----------|")
    for name in rows:
        rate = statistics.median(rates[name])
        size = f"{sizes[name] / 1024:8.2f}" if name in sizes else f"{'-':>8}"
        print(f"| {name:<38} | {rate:7.0f} | {1000 / rate:7.2f} | {size} | {base / rate:7.2f}x |")
    env.close()
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
