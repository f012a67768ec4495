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
* ``egl process`` / ``osmesa process``: one RoomNav environment in a fresh
  process with ``MUJOCO_GL`` set to that backend (the backend is fixed when
  MuJoCo is imported, so each runs in its own process), rounds interleaved;
  ``rel`` is against the EGL process. Skipped for a backend whose library is
  missing.
* ``vector W x K``: total steps/s of ``W`` worker processes holding ``K``
  environments each (:class:`leaps_mj.environment.vector.VectorEnv`: one
  message per worker per step, frames through shared memory), every worker
  stepped in lock-step; ``vector W x K async``: the same served through
  ``recv`` / ``send``, each worker stepped again as soon as it replies.
  ``pin``: each worker bound to one CPU (``VectorEnv(pin=True)``).
  Their ``rel`` is the median over rounds of the ratio to the same ``W * K``
  environments (same seeds, so the same houses) stepped in turn in this
  process, measured right before each round: the houses differ in drawing
  cost, so a single environment of another house is no baseline (the other
  rows' ``rel`` compare medians with ``roomnav``).

    python benchmarks/env_throughput.py [--dataset roomnav-v2] [--seconds 3] [--rounds 3]
"""

from __future__ import annotations

import argparse
import ctypes.util
import os
import statistics
import subprocess
import sys
import time

import numpy as np

import leaps_mj
from leaps_mj.environment import vector
from leaps_mj.world import dataset, rooms


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


def in_process_stepper(dataset, num_envs, width, height):
    """Environments ``0 .. num_envs - 1`` of a vector env (the same seeds, so the same houses), stepped in
    turn in this process: what the vector env is compared with."""
    envs = [leaps_mj.load(dataset, "train", seed=i, width=width, height=height, horizon=10**9)
            for i in range(num_envs)]
    for env in envs:
        env.reset()
    rng = np.random.default_rng(0)
    turn = [0]

    def step():
        envs[turn[0] % num_envs].step(int(rng.integers(rooms.NUM_ACTIONS)))
        turn[0] += 1

    return envs, step


def vector_rates(dataset, workers, per_worker, width, height, seconds, rounds, mode="lock-step", pin=False):
    """Median steps/s of a vector env, and its median ratio to the same environments stepped in turn in
    this process, measured right before it in each round."""
    n = workers * per_worker
    rates, ratios = [], []
    envs, single = in_process_stepper(dataset, n, width, height)
    _rate(single, 0.5)
    with vector.VectorEnv(n, seed=0, num_workers=workers, dataset=dataset, split="train", width=width,
                          height=height, horizon=10**9, pin=pin) as venv:
        rng = np.random.default_rng(0)
        if mode == "lock-step":
            venv.reset()
            step = lambda: venv.step(list(rng.integers(rooms.NUM_ACTIONS, size=n)))  # noqa: E731
        else:  # serve whichever worker finished first
            venv.async_reset()

            def step():
                ids, _ = venv.recv()
                venv.send(ids, list(rng.integers(rooms.NUM_ACTIONS, size=len(ids))))
        _rate(step, 0.5)  # warm-up: compiles each worker's first houses
        for _ in range(rounds):
            alone = _rate(single, seconds)
            # Each async step serves one worker's per_worker environments; a lock-step one all n.
            rates.append((n if mode == "lock-step" else per_worker) * _rate(step, seconds))
            ratios.append(rates[-1] / alone)
    for env in envs:
        env.close()
    return statistics.median(rates), statistics.median(ratios)


#: How the vector rows with several workers are stepped: (lock-step or async, workers pinned to CPUs).
VARIANTS = (("lock-step", False), ("async", False), ("lock-step", True), ("async", True))


#: Steps one environment for argv[4] seconds after a warm-up and prints its steps/s.
_BACKEND_PROBE = """
import sys, time, numpy as np, leaps_mj
env = leaps_mj.load(sys.argv[1], "train", seed=0, width=int(sys.argv[2]), height=int(sys.argv[3]), horizon=10**9)
rng = np.random.default_rng(0)
env.reset()
def run(seconds):
    n, t0 = 0, time.perf_counter()
    while time.perf_counter() - t0 < seconds:
        env.step(int(rng.integers(9)))
        n += 1
    return n / (time.perf_counter() - t0)
run(0.5)
print(run(float(sys.argv[4])))
env.close()
"""


def backend_rates(dataset, width, height, seconds, rounds) -> dict[str, float]:
    """Median steps/s of one environment per off-screen backend, each in its own process, interleaved."""
    backends = [b for b, lib in (("egl", "EGL"), ("osmesa", "OSMesa")) if ctypes.util.find_library(lib)]
    rates = {b: [] for b in backends}
    for _ in range(rounds):
        for backend in backends:
            env = {k: v for k, v in os.environ.items() if k not in ("PYOPENGL_PLATFORM", "LEAPS_MJ_GL_PROBLEM")}
            env["MUJOCO_GL"] = backend
            out = subprocess.run([sys.executable, "-c", _BACKEND_PROBE, dataset, str(width), str(height),
                                  str(seconds)], env=env, capture_output=True, text=True, check=True)
            rates[backend].append(float(out.stdout.split()[-1]))
    return {b: statistics.median(v) for b, v in rates.items()}


def main(argv=None):
    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--dataset", default=dataset.CANONICAL)
    p.add_argument("--seconds", type=float, default=3.0, help="per measurement")
    p.add_argument("--rounds", type=int, default=3)
    p.add_argument("--workers", type=int, nargs="*", default=[1, 2], help="worker processes of the vector rows")
    p.add_argument("--per-worker", type=int, nargs="*", default=[1, 4, 8], help="environments per worker")
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
        backends = backend_rates(args.dataset, width, height, args.seconds, args.rounds)
        for backend, v in backends.items():
            rows.append((f"{width}x{height}", f"{backend} process", f"{v:,.0f}", f"{v / backends['egl']:.2f}"
                         if "egl" in backends else "-"))
        for w in args.workers:
            for k in args.per_worker:
                for mode, pin in (VARIANTS if w > 1 else VARIANTS[:1]):
                    v, ratio = vector_rates(args.dataset, w, k, width, height, args.seconds, args.rounds, mode,
                                            pin)
                    name = f"vector {w} x {k}" + (" async" if mode == "async" else "") + (" pin" if pin else "")
                    rows.append((f"{width}x{height}", name, f"{v:,.0f}", f"{ratio:.2f}"))

    print(f"\nsteps/s, median of {args.rounds} interleaved rounds of {args.seconds:g} s "
          "(rel = rate / roomnav single-process rate at that resolution; for the vector rows, "
          "median ratio to the same environments stepped in turn in this process)\n")
    print(f"| {'resolution':<10} | {'what':<22} | {'steps/s':>9} | {'rel':>6} |")
    print(f"|{'-' * 12}|{'-' * 24}|{'-' * 11}|{'-' * 8}|")
    for r in rows:
        print(f"| {r[0]:<10} | {r[1]:<22} | {r[2]:>9} | {r[3]:>6} |")
    print()
    print("\n".join(notes))


if __name__ == "__main__":
    main()
