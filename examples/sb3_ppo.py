"""PPO from Stable-Baselines3 on RoomNav, through the registered gymnasium id as it is.

    pip install -e ".[all]"      # stable-baselines3 is in the `sb3` extra
    python examples/sb3_ppo.py --steps 20000 --num-envs 2 --out runs/sb3_ppo

Trains ``MultiInputPolicy`` (a NatureCNN per image entry, segmentation and
depth, plus the bits) on the training houses at 64x48, with the shaped
training reward, starts at most ``--max-start`` geodesic metres from the
target and ``--horizon``-step episodes. Writes ``<out>/ppo_roomnav.zip`` (the
model), ``<out>/monitor.csv`` (one row per finished episode: return, length,
success) and ``<out>/learning_curve.png`` (success rate and return against
environment steps). With ``--num-envs`` above 1 the environments run in
spawned worker processes (SB3's ``SubprocVecEnv``), one per core.
"""

from __future__ import annotations

import argparse
import csv
import pathlib
import sys

import gymnasium
import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402
from stable_baselines3 import PPO  # noqa: E402
from stable_baselines3.common.monitor import Monitor  # noqa: E402
from stable_baselines3.common.vec_env import DummyVecEnv, SubprocVecEnv  # noqa: E402

import leaps_mj.gym_adapter  # noqa: E402,F401  (registers leaps_mj/RoomNav-v1)


class _EnvFactory:
    """Builds one monitored environment (picklable, for worker processes)."""

    def __init__(self, kwargs: dict, monitor: str):
        self.kwargs, self.monitor = kwargs, monitor

    def __call__(self):
        env = gymnasium.make("leaps_mj/RoomNav-v1", **self.kwargs)
        return Monitor(env, self.monitor, info_keywords=("success",))


def read_monitor(folder: pathlib.Path) -> list[dict]:
    """Finished episodes of every worker's monitor file, in order of wall time."""
    rows = []
    for path in sorted(folder.glob("*.monitor.csv")):
        with open(path) as f:
            next(f)  # the JSON header line
            rows += [{"r": float(r["r"]), "l": int(r["l"]), "t": float(r["t"]), "success": r["success"] == "True"}
                     for r in csv.DictReader(f)]
    return sorted(rows, key=lambda r: r["t"])


def plot_curve(rows: list[dict], path: pathlib.Path, window: int = 50) -> None:
    """Success rate and return (moving averages over ``window`` episodes) against environment steps."""
    steps = np.cumsum([r["l"] for r in rows])
    fig, (a, b) = plt.subplots(1, 2, figsize=(9, 3.2))
    for ax, key, label in ((a, "success", "success rate"), (b, "r", "episode return")):
        values = np.array([float(r[key]) for r in rows])
        w = max(1, min(window, len(values)))
        smooth = np.convolve(values, np.ones(w) / w, mode="valid")
        ax.plot(steps[w - 1:], smooth)
        ax.set_xlabel("environment steps")
        ax.set_ylabel(f"{label} (mean of {w} episodes)")
        ax.grid(alpha=0.3)
    fig.suptitle("PPO (Stable-Baselines3) on RoomNav-MJ, 64x48")
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)


def main(argv=None) -> int:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("--steps", type=int, default=20_000, help="environment steps of training")
    p.add_argument("--num-envs", type=int, default=2, help="environments (worker processes when > 1)")
    p.add_argument("--out", type=pathlib.Path, default=pathlib.Path("runs/sb3_ppo"))
    p.add_argument("--dataset", default=None, help="dataset name or folder (default: the canonical one)")
    p.add_argument("--width", type=int, default=64)
    p.add_argument("--height", type=int, default=48)
    p.add_argument("--horizon", type=int, default=100, help="steps of a training episode")
    p.add_argument("--max-start", type=float, default=6.0, help="largest start distance to the target (metres)")
    p.add_argument("--n-steps", type=int, default=256, help="PPO rollout length per environment")
    p.add_argument("--seed", type=int, default=0)
    args = p.parse_args(argv)
    for name in ("steps", "num_envs", "n_steps"):
        if getattr(args, name) < 1:
            p.error(f"--{name.replace('_', '-')} {getattr(args, name)}: expected a positive integer")
    args.out.mkdir(parents=True, exist_ok=True)
    env_kwargs = dict(split="train", width=args.width, height=args.height, horizon=args.horizon,
                      max_start_distance=args.max_start, reward="shaped")
    if args.dataset is not None:
        env_kwargs["dataset"] = args.dataset
    factories = [_EnvFactory(dict(env_kwargs, seed=args.seed + i), str(args.out / f"env{i}"))
                 for i in range(args.num_envs)]
    venv = SubprocVecEnv(factories, start_method="spawn") if args.num_envs > 1 else DummyVecEnv(factories)
    venv.seed(args.seed)
    model = PPO("MultiInputPolicy", venv, n_steps=args.n_steps, batch_size=min(64, args.n_steps * args.num_envs),
                n_epochs=4, learning_rate=3e-4, ent_coef=0.01, seed=args.seed, device="cpu", verbose=0)
    model.learn(args.steps, progress_bar=False)
    model.save(args.out / "ppo_roomnav.zip")
    venv.close()
    rows = read_monitor(args.out)
    with open(args.out / "monitor.csv", "w", newline="") as f:
        writer = csv.DictWriter(f, ["r", "l", "t", "success"])
        writer.writeheader()
        writer.writerows(rows)
    if rows:
        plot_curve(rows, args.out / "learning_curve.png")
        last = rows[-100:]
        print(f"{len(rows)} episodes; last {len(last)}: success {np.mean([r['success'] for r in last]):.2f}, "
              f"return {np.mean([r['r'] for r in last]):.2f}")
    print(f"wrote {args.out / 'ppo_roomnav.zip'}, {args.out / 'monitor.csv'}"
          + (f", {args.out / 'learning_curve.png'}" if rows else ""))
    return 0


if __name__ == "__main__":
    sys.exit(main())
