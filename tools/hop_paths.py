"""Hop episodes drawn on their house plans: the map-goal sub-policy's path and goals beside the oracle's path.

``python tools/hop_paths.py results/hops_large_contnear8_v2_test --large --room indoor --count 6 --out FILE.png``

Tables say how often the sub-policy fails a hop (``python tools/hop_visibility.py`` says where); this shows
how. From a hop result folder (written by ``python -m leaps_mj.evaluation.hops`` with the map-goal
sub-policy as ``pure``) it draws a seeded sample of ``--count`` episodes ``--distance`` doors from the
target, optionally only those starting in a room of type ``--room`` (``indoor``: a hallway) and only the
failed or the successful ones (``--outcome``; success within ``--horizon`` steps). Each episode is run
again in this process as the evaluation ran it, and must take the steps the folder records (else the
folder's sub-policy, or the code, has changed since and the picture would not be of its runs). One panel
per episode: the house around the start, the sub-policy's path (blue) and the goals it chose on its map
(orange, darker later), the geodesic oracle's path (grey, dashed) and the rooms of the target's type
(outlined red).
"""

from __future__ import annotations

import argparse
import dataclasses
import json
import math
import pathlib
import sys

import matplotlib.patches as mpatches
import matplotlib.pyplot as plt
import numpy as np

sys.path.insert(0, str(pathlib.Path(__file__).resolve().parent))

import hop_visibility  # noqa: E402  (a sibling script of tools/)

from leaps_mj.environment import episodes as episodes_lib  # noqa: E402
from leaps_mj.evaluation import harness, stats  # noqa: E402
from leaps_mj.world import topdown  # noqa: E402

#: Which episodes ``--outcome`` keeps.
OUTCOMES = ("failed", "succeeded", "all")
#: Panels per row of the figure.
COLUMNS = 3
#: Metres of the house shown around the paths.
MARGIN = 2.5


class Trace:
    """An episode observer keeping the agent's poses and, for a map-goal sub-policy, each goal it chose."""

    def __init__(self):
        self.runs: list[dict] = []

    def begin(self, env, spec, agent):
        self._subpolicy = getattr(agent, "subpolicy", None)
        self.runs.append({"poses": [np.array(env.physics.agent_pose())], "goals": []})

    def step(self, timestep, action, info):
        run = self.runs[-1]
        run["poses"].append(np.asarray(timestep.observation["pose"], dtype=float))
        goal = getattr(self._subpolicy, "goal", None)
        if goal is not None and (not run["goals"] or not np.allclose(run["goals"][-1], goal)):
            run["goals"].append(goal)

    def end(self, result):
        self.runs[-1]["result"] = result


def folder_config(folder: pathlib.Path, kind: str, policy_dir: str | None) -> harness.EvalConfig:
    """The evaluation configuration a hop result folder ran, with its sub-policy folder replaced by ``policy_dir``.

    Raises:
      ValueError: for a folder that is not a hop result folder of the episodes ``kind``, or holds no ``pure`` rows.
    """
    saved = json.loads((folder / "config.json").read_text()) if (folder / "config.json").is_file() else {}
    hop_visibility.check_folder(folder, str(saved.get("dataset")), str(saved.get("split")), kind)
    if not (folder / "episodes_pure.csv").is_file():
        raise ValueError(f"{str(folder)!r} holds no episodes_pure.csv: expected a hop run of the agent 'pure'")
    config = harness.EvalConfig(**{**harness.LATER_FIELDS, **saved})
    if policy_dir is not None:
        config = dataclasses.replace(config, policy_dir=policy_dir)
    return config


def choose(rows: list[dict], group_of: dict[int, str], room: str | None, outcome: str, horizon: int,
           count: int, seed: int) -> list[int]:
    """A seeded draw of ``count`` episodes of ``group_of`` (start room ``room`` if given) with the ``outcome``.

    Raises:
      ValueError: if none is left to draw.
    """
    ok = dict(zip((r["episode"] for r in rows), stats.success_at(rows, horizon)))
    pool = sorted(i for i in group_of if i in ok and (room is None or group_of[i] == room)
                  and (outcome == "all" or ok[i] == (outcome == "succeeded")))
    if not pool:
        raise ValueError(f"no {outcome} episode starts in a room of type {room!r} (within {horizon} steps)")
    picked = np.random.default_rng(seed).choice(pool, size=min(count, len(pool)), replace=False)
    return sorted(int(i) for i in picked)


def trace(config: harness.EvalConfig, agent: str, indices: list[int], recorded: dict[int, dict] | None = None):
    """Each episode's :class:`Trace` run of ``agent``; with ``recorded`` rows, checked to take their steps.

    Raises:
      ValueError: where a run takes other steps than the folder records.
    """
    tracer = Trace()
    rows = harness.run_observed(config, harness.AGENTS[agent], indices, tracer)
    for row in rows if recorded is not None else ():
        want = recorded[row["episode"]]
        if (row["steps"], row["success_step"]) != (want["steps"], want["success_step"]):
            raise ValueError(f"episode {row['episode']} ran {row['steps']} steps (success at {row['success_step']}) "
                             f"here, the folder records {want['steps']} ({want['success_step'] or 'none'}): its "
                             f"sub-policy {config.policy_dir!r} or the code changed since; pass --policy-dir")
    return dict(zip(indices, tracer.runs))


def _panel(ax, house, spec, run: dict, oracle: dict, horizon: int) -> None:
    """One episode: the house around the paths, the oracle's path, the sub-policy's path and goals."""
    topdown.draw_house(ax, house, furniture_labels=False)
    for text in ax.texts:  # room names outside the cropped view would spill over the neighbouring panels
        text.set_clip_on(True)
    for room in house.rooms:
        if room.type == spec.target:
            x0, y0, x1, y1 = room.rect
            ax.add_patch(mpatches.Rectangle((x0, y0), x1 - x0, y1 - y0, fill=False, ec="tab:red", lw=2.2, zorder=4,
                                            label="rooms of the target's type"))
    path, best = np.array(run["poses"])[:, :2], np.array(oracle["poses"])[:, :2]
    ax.plot(*best.T, color="0.35", lw=1.6, ls="--", zorder=5, label="geodesic oracle")
    ax.plot(*path.T, color="tab:blue", lw=2.0, zorder=6, label="map-goal sub-policy")
    goals = np.array(run["goals"]).reshape(-1, 2)
    ax.scatter(*goals.T, c=np.linspace(0.3, 1.0, len(goals)), cmap="Oranges", vmin=0, vmax=1, s=18,
               edgecolors="black", linewidths=0.4, zorder=7, label="its goals (darker later)")
    x, y, yaw = spec.start
    ax.annotate("", xy=(x + 0.8 * math.cos(yaw), y + 0.8 * math.sin(yaw)), xytext=(x, y), zorder=8,
                arrowprops=dict(arrowstyle="-|>", color="black", lw=1.5))
    ax.plot(x, y, "o", color="black", ms=6, zorder=8, label="start, facing")
    seen = np.vstack([path, best, goals])
    ax.set_xlim(seen[:, 0].min() - MARGIN, seen[:, 0].max() + MARGIN)
    ax.set_ylim(seen[:, 1].min() - MARGIN, seen[:, 1].max() + MARGIN)
    step = run["result"]["success_step"]
    outcome = f"reached at step {step}" if step is not None and step <= horizon else f"not reached in {horizon}"
    ax.set_title(f"{spec.house}: to the {spec.target.replace('_', ' ')}, {spec.geodesic:.1f} m\n{outcome} "
                 f"(oracle: {oracle['result']['success_step']})", fontsize=8)
    ax.set_xlabel("")
    ax.set_ylabel("")


def figure(specs, houses: dict, runs: dict, oracles: dict, horizon: int, title: str):
    """The panels of the episodes ``runs`` holds, in a grid, with one legend."""
    rows = -(-len(runs) // COLUMNS)
    fig, axes = plt.subplots(rows, COLUMNS, figsize=(5 * COLUMNS, 4.6 * rows), squeeze=False, layout="constrained")
    for ax, i in zip(axes.flat, runs):
        _panel(ax, houses[specs[i].house], specs[i], runs[i], oracles[i], horizon)
    for ax in axes.flat[len(runs):]:
        ax.axis("off")
    handles, labels = axes.flat[0].get_legend_handles_labels()
    fig.legend(handles, labels, loc="outside lower center", ncol=4, fontsize=8)
    fig.suptitle(title, fontsize=10)
    return fig


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("folder", type=pathlib.Path, help="a hop result folder (python -m leaps_mj.evaluation.hops --out)")
    parser.add_argument("--out", type=pathlib.Path, required=True, help="PNG file")
    parser.add_argument("--large", action="store_true", help="the folder ran the large hop set")
    parser.add_argument("--policy-dir", default=None,
                        help="the sub-policy folder to run (default: the folder's), e.g. the shipped copy of a run's")
    parser.add_argument("--distance", type=int, default=1, help="doors from the target (1 or 2)")
    parser.add_argument("--horizon", type=int, default=60, help="success within this many steps")
    parser.add_argument("--room", default=None, help="only starts in a room of this type (indoor: a hallway)")
    parser.add_argument("--outcome", choices=OUTCOMES, default="failed")
    parser.add_argument("--count", type=int, default=6, help="episodes drawn")
    parser.add_argument("--seed", type=int, default=0, help="seed of the draw")
    args = parser.parse_args(argv)
    if args.distance not in episodes_lib.HOP_DISTANCES or args.horizon < 1 or args.count < 1:
        parser.error(f"--distance {args.distance}, --horizon {args.horizon}, --count {args.count}: expected a "
                     f"distance in {list(episodes_lib.HOP_DISTANCES)} and a positive horizon and count")
    kind = "hops_large" if args.large else "hops"
    try:
        config = folder_config(args.folder, kind, args.policy_dir)
        if args.horizon > config.horizon:
            raise ValueError(f"--horizon {args.horizon}: the folder's episodes ran {config.horizon} steps at most")
        rows = harness.read_rows(args.folder / "episodes_pure.csv")
        group_of = hop_visibility.groups(config.dataset, config.split, args.distance, "room", kind)
        picked = choose(rows, group_of, args.room, args.outcome, args.horizon, args.count, args.seed)
        runs = trace(config, "pure", picked, {r["episode"]: r for r in rows})
        oracles = trace(config, "oracle", picked)
    except ValueError as e:
        print(f"error: {e}", file=sys.stderr)
        return 2
    specs = episodes_lib.load_split(config.dataset, config.split, kind)
    houses = {hm.house.id: hm.house for hm in episodes_lib.house_models(config.dataset, config.split)}
    where = f"starts in a room of type {args.room}" if args.room else "starts"
    title = (f"{config.split} hops {args.distance} door(s) from the target, {args.outcome} {where} "
             f"(episodes {', '.join(map(str, picked))}); sub-policy {config.policy_dir}")
    topdown.save_figure(figure(specs, houses, runs, oracles, args.horizon, title), args.out, dpi=110)
    print(f"wrote {args.out}: episodes {picked}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
