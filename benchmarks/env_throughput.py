"""Environment throughput: RoomNav vs a bare MuJoCo render loop vs MiniWorld.

Prints one table, every row measured in this run, interleaved over rounds
(median reported) so that a noisy shared machine affects all rows alike:

* ``roomnav``: env steps/s of one RoomNav environment (random actions, fixed
  seed), one process.
* ``bare render``: the same house, the same poses, only MuJoCo kinematics +
  the one-pass segmentation/depth render: the floor under the env's cost.
  ``roomnav / bare`` is the env's overhead.
* ``env work only``: the RoomNav environment with its render call replaced
  by a copy of one cached frame: the cost of everything the env does besides
  drawing (collision-checked move, label lookup, see test, geodesic, bits,
  observation), also printed in µs per step.
* ``miniworld``: Farama MiniWorld FourRooms at the same resolution (RGB), the
  lightweight peer (``pip install miniworld``; rendered headless through
  pyglet's EGL mode). Skipped with a note when not installed.
* ``vector xN``: total steps/s of N worker processes.

    python benchmarks/env_throughput.py [--dataset roomnav-v1] [--seconds 3] [--rounds 3]
"""

from __future__ import annotations

import argparse
import statistics
import time

import numpy as np

import leaps_mj
from leaps_mj.environment import vector
from leaps_mj.world import rooms


def _rate(fn, seconds: float) -> float:
    n, t0 = 0, time.perf_counter()
    while time.perf_counter() - t0 < seconds:
        fn()
        n += 1
    return n / (time.perf_counter() - t0)


def roomnav_stepper(dataset, width, height, seed=0):
    # One long episode: the rate of stepping, not of compiling houses at resets.
    env = leaps_mj.load(dataset, "train", seed=seed, width=width, height=height, horizon=10**9)
    rng = np.random.default_rng(seed)
    env.reset()
    poses = []

    def step():
        env.step(int(rng.integers(rooms.NUM_ACTIONS)))
        poses.append(env.physics.agent_pose())

    return env, step, poses


def bare_render_stepper(env, poses):
    """Sets recorded poses and renders, with nothing else of the env."""
    physics, renderer = env.physics, env.renderer
    k = [0]

    def step():
        physics.data.qpos[:3] = poses[k[0] % len(poses)]
        physics.forward_kinematics()
        renderer.render(physics.data.ptr)
        k[0] += 1

    return step


def env_work_stepper(dataset, width, height, seed=0):
    """A RoomNav stepper whose renderer hands back one cached frame instead of drawing."""
    env, step, _ = roomnav_stepper(dataset, width, height, seed)
    seg, depth = env.renderer.render_segments(env.physics.data.ptr)
    env.renderer.render_segments = lambda data: (seg.copy(), depth.copy())
    return env, step


def miniworld_stepper(width, height, seed=0):
    try:
        import pyglet

        pyglet.options["headless"] = True
        import gymnasium
        import miniworld  # noqa: F401
    except ImportError as e:
        return None, f"miniworld not installed ({e})"
    env = gymnasium.make("MiniWorld-FourRooms-v0", obs_width=width, obs_height=height)
    env.reset(seed=seed)
    env.action_space.seed(seed)

    def step():
        _, _, term, trunc, _ = env.step(env.action_space.sample())
        if term or trunc:
            env.reset()

    return step, None


def vector_rate(dataset, n, width, height, seconds):
    with vector.VectorEnv(n, seed=0, dataset=dataset, split="train", width=width, height=height,
                          horizon=10**9) as venv:
        venv.reset()
        rng = np.random.default_rng(0)
        return n * _rate(lambda: venv.step(list(rng.integers(rooms.NUM_ACTIONS, size=n))), seconds)


def main(argv=None):
    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--dataset", default="roomnav-v1")
    p.add_argument("--seconds", type=float, default=3.0, help="per measurement")
    p.add_argument("--rounds", type=int, default=3)
    p.add_argument("--workers", type=int, nargs="*", default=[1, 2])
    args = p.parse_args(argv)

    rows, notes = [], []
    for width, height in ((120, 90), (64, 48)):
        env, env_step, poses = roomnav_stepper(args.dataset, width, height)
        _rate(env_step, 0.5)  # warm-up: compiles the first houses, records poses
        bare = bare_render_stepper(env, poses)
        work_env, work = env_work_stepper(args.dataset, width, height)
        mw, note = miniworld_stepper(width, height)
        rates = {"roomnav": [], "bare render": [], "env work only": [], "miniworld": []}
        for _ in range(args.rounds):
            rates["roomnav"].append(_rate(env_step, args.seconds))
            rates["bare render"].append(_rate(bare, args.seconds))
            rates["env work only"].append(_rate(work, args.seconds))
            if mw is not None:
                rates["miniworld"].append(_rate(mw, args.seconds))
        env.close()
        work_env.close()
        med = {k: statistics.median(v) for k, v in rates.items() if v}
        notes.append(f"{width}x{height}: env work {1e6 / med['env work only']:.0f} us/step; "
                     f"roomnav / bare render = {med['roomnav'] / med['bare render']:.2f}")
        for k, v in med.items():
            rel = f"{v / med['roomnav']:.2f}" if k != "roomnav" else "1.00"
            rows.append((f"{width}x{height}", k, f"{v:,.0f}", rel))
        if note:
            rows.append((f"{width}x{height}", "miniworld", "-", note))
        for n in args.workers:
            v = vector_rate(args.dataset, n, width, height, args.seconds)
            rows.append((f"{width}x{height}", f"vector x{n}", f"{v:,.0f}", f"{v / med['roomnav']:.2f}"))

    print(f"\nsteps/s, median of {args.rounds} interleaved rounds of {args.seconds:g} s "
          "(rel = rate / roomnav single-process rate at that resolution)\n")
    print(f"| {'resolution':<10} | {'what':<13} | {'steps/s':>9} | {'rel':>6} |")
    print(f"|{'-' * 12}|{'-' * 15}|{'-' * 11}|{'-' * 8}|")
    for r in rows:
        print(f"| {r[0]:<10} | {r[1]:<13} | {r[2]:>9} | {r[3]:>6} |")
    print()
    print("\n".join(notes))


if __name__ == "__main__":
    main()
