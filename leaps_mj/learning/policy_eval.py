"""Evaluation and figures of sub-policy runs: success on sampled episodes, training curves.

Used by the trainer once a target is trained (the results go into its
checkpoint) and by the docs' figures.
"""

from __future__ import annotations

import csv
import math
import os
import pathlib
from typing import Any, Sequence

import numpy as np

from leaps_mj.environment import roomnav
from leaps_mj.learning import checkpoints
from leaps_mj.learning.policy_config import TrainConfig


def evaluate(subpolicies: dict[str, Any], targets: Sequence[str], config: TrainConfig, split: str,
             seed: int) -> dict[str, dict[str, float]]:
    """Success of sub-policies on the same sampled episodes of a split (sparse reward).

    Starts lie within the distance the curriculum reached at the end of
    training (and within ``config.max_start_doors`` doors, where set);
    episodes last ``config.eval_horizon`` steps and draw their target among
    ``targets`` present in the house.

    Args:
      subpolicies: Sub-policies (``reset(target)``, ``act(timestep)``) by name.
      targets: Target room types.
      config: The run's configuration.
      split: "train" or "valid".
      seed: Seed of the episode draws.

    Returns:
      For each name: {"success_rate", "episodes", "mean_steps", "max_start_distance"}.
    """
    distance = config.start_distance_at(config.iterations - 1)
    env = roomnav.load(config.dataset, split, seed=seed, width=config.width, height=config.height,
                        horizon=config.eval_horizon, reward="sparse", targets=tuple(targets),
                        max_start_distance=distance, max_start_doors=config.max_start_doors or None)
    outcomes = {name: [] for name in subpolicies}
    try:
        for _ in range(config.eval_episodes):
            spec = env.sample_episode()
            for name, policy in subpolicies.items():
                ts = env.reset_to(spec)
                policy.reset(spec.target)
                while not ts.last():
                    ts = env.step(policy.act(ts))
                outcomes[name].append((ts.discount == 0.0, env.task.steps))
    finally:
        env.close()
    return {name: {"success_rate": float(np.mean([s for s, _ in out])), "episodes": len(out),
                   "mean_steps": float(np.mean([n for _, n in out])), "max_start_distance": distance}
            for name, out in outcomes.items()}


def read_progress(path: str | os.PathLike) -> dict[str, np.ndarray]:
    """Columns of a ``progress.csv`` as float arrays (NaN where empty; phase as strings)."""
    with open(path, newline="") as f:
        rows = list(csv.DictReader(f))
    out = {}
    for key in rows[0] if rows else ():
        if key == "phase":
            out[key] = np.array([r[key] for r in rows])
        else:
            out[key] = np.array([float(r[key]) if r[key] != "" else np.nan for r in rows])
    return out


def plot_curves(out: str | os.PathLike, targets: Sequence[str], path: str | os.PathLike) -> None:
    """One panel per target: rollout success of learner- and expert-driven episodes, β and distance."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    from leaps_mj.world import topdown

    cols = min(3 if len(targets) == 9 else 4, len(targets))
    rows_ = math.ceil(len(targets) / cols)
    fig, axes = plt.subplots(rows_, cols, figsize=(4.2 * cols, 3.2 * rows_), squeeze=False)
    for ax, target in zip(axes.flat, targets):
        log = read_progress(pathlib.Path(out) / target / "progress.csv")
        steps = log["global_step"] / 1000
        ax.plot(steps, log["success_rate"], color="C0", label="success (learner drives)")
        if not np.all(np.isnan(log["mixed_success_rate"])):
            ax.plot(steps, log["mixed_success_rate"], color="C2", alpha=0.6, label="success (expert steps w.p. β)")
        ax.plot(steps, log["beta"], color="C7", ls=":", label="β")
        a2c = np.flatnonzero(log["phase"] == "a2c")
        if len(a2c) and a2c[0] > 0:
            ax.axvline(steps[a2c[0]], color="C3", ls="--", lw=1, label="DAgger → A2C")
        ax.set_ylim(-0.02, 1.02)
        ax.set_title(target)
        ax.set_xlabel("env steps (k)")
        twin = ax.twinx()
        twin.plot(steps, log["start_distance"], color="C1", lw=1, label="max start distance (m)")
        twin.set_ylim(0, max(1.0, np.nanmax(log["start_distance"]) * 1.1))
        twin.tick_params(labelsize=7, colors="C1")
    for ax in axes.flat[len(targets):]:
        ax.axis("off")
    handles, labels = axes.flat[0].get_legend_handles_labels()
    handles.append(matplotlib.lines.Line2D([], [], color="C1", lw=1))
    labels.append("max start distance (m, right axis)")
    fig.legend(handles, labels, loc="lower center", ncol=5, fontsize=8, bbox_to_anchor=(0.5, -0.02))
    fig.suptitle("Sub-policy training: success of rollout episodes (last 50 episodes)")
    fig.tight_layout(rect=(0, 0.04, 1, 1))
    topdown.save_figure(fig, path)


def plot_comparison(runs: dict[str, str | os.PathLike], target: str, path: str | os.PathLike) -> None:
    """Success of learner-driven rollout episodes of one target, for runs of several methods.

    Args:
      runs: Output folders by label (e.g. {"DAgger": "runs/policy_cpu", "A2C": ...}).
      target: The target trained in every run.
      path: PNG to write.
    """
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    from leaps_mj.world import topdown

    fig, ax = plt.subplots(figsize=(6.5, 3.8))
    for i, (label, folder) in enumerate(runs.items()):
        log = read_progress(pathlib.Path(folder) / target / "progress.csv")
        _, _, extra = checkpoints.load_policy(pathlib.Path(folder) / f"{target}.pt")
        valid = (extra.get("eval") or {}).get("valid/sampled", {}).get("success_rate")
        suffix = f" (valid eval {valid:.2f})" if valid is not None else ""
        ax.plot(log["global_step"] / 1000, log["success_rate"], color=f"C{i}", label=label + suffix)
    ax.set_xlabel("env steps (k)")
    ax.set_ylabel("success of learner-driven episodes")
    ax.set_ylim(-0.02, 1.02)
    ax.set_title(f"{target}: methods on the same budget (last 50 episodes)")
    ax.legend(fontsize=8)
    topdown.save_figure(fig, path)
