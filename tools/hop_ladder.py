"""Hop success of several agents side by side: a ladder from what the agent senses to what the plan shows.

``python tools/hop_ladder.py --run "shipped network=results/hops_goal_SClos_v2_test"
--run "gated teacher=results/hops_oracle_map_sensed_v2_test#oracle-map-gated" ... --out docs/img/hop_ladder.png``

Each ``--run LABEL=FOLDER[#AGENT]`` names a result folder of ``python -m leaps_mj.evaluation.hops`` (its
``summary.json``) and the agent whose success to show (default ``pure``, the sub-policy). One horizontal
bar per run and door distance, success within 60 steps (light) and 30 steps (dark) with 95 % Wilson
intervals, in the order given, and issue 13's goal (80 % of the one-door hops within 60 steps) as a
line. All folders must be hop runs of one dataset, split and seed (the same episodes); the tool prints
the plotted numbers as a table.
"""

from __future__ import annotations

import argparse
import json
import pathlib
import sys

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402  (after the backend is chosen)

#: Door distances (panels) and step budgets (bars) shown.
DOORS, HORIZONS = ("1", "2"), ("30", "60")
#: Issue 13's goal: 80 % of the one-door hops within 60 steps.
GOAL = 0.8


def parse_run(text: str) -> tuple[str, pathlib.Path, str]:
    """``LABEL=FOLDER[#AGENT]`` → (label, folder, agent); a clear error otherwise."""
    label, sep, rest = text.partition("=")
    folder, _, agent = rest.partition("#")
    if not sep or not label or not folder:
        raise argparse.ArgumentTypeError(f"--run {text!r}: expected LABEL=FOLDER or LABEL=FOLDER#AGENT")
    if not (pathlib.Path(folder) / "summary.json").is_file():
        raise argparse.ArgumentTypeError(f"--run {text!r}: {folder!r} holds no summary.json; expected a result "
                                         "folder of python -m leaps_mj.evaluation.hops")
    return label, pathlib.Path(folder), agent or "pure"


def load(runs: list[tuple[str, pathlib.Path, str]]) -> list[dict]:
    """One row per run: label, folder, agent, split and the success of each (doors, horizon).

    Raises:
      ValueError: if a folder is not a hop run, lacks the agent, or ran other episodes than the first.
    """
    rows, first = [], None
    for label, folder, agent in runs:
        doc = json.loads((folder / "summary.json").read_text())
        key = {k: doc["config"].get(k) for k in ("dataset", "split", "seed", "episodes")}
        if key["episodes"] != "hops" or agent not in doc["success"]:
            raise ValueError(f"{str(folder)!r}: not a hop benchmark run of agent {agent!r} ({key}; agents "
                             f"{sorted(doc['success'])})")
        if first is not None and key != first[1]:
            raise ValueError(f"{str(folder)!r} ran other episodes ({key}) than {str(first[0])!r} ({first[1]})")
        first = first or (folder, key)
        success = doc["success"][agent]
        rows.append({"label": label, "folder": str(folder), "agent": agent, "split": key["split"],
                     "rates": {(d, h): success[h][d]["all"] for d in DOORS for h in HORIZONS}})
    return rows


def plot(rows: list[dict], out: pathlib.Path) -> None:
    """One panel per door distance, a pair of bars (≤ 60 light, ≤ 30 dark) per run."""
    fig, axes = plt.subplots(1, len(DOORS), figsize=(12, 0.45 * len(rows) + 1.6), sharey=True,
                             layout="constrained")
    y = list(range(len(rows)))[::-1]
    for ax, doors in zip(axes, DOORS):
        for horizon, colour in zip(HORIZONS[::-1], ("#9ecae1", "#3182bd")):
            rates = [r["rates"][(doors, horizon)] for r in rows]
            ax.barh(y, [v["rate"] for v in rates], color=colour, height=0.7, label=f"≤ {horizon} steps",
                    xerr=[[v["rate"] - v["low"] for v in rates], [v["high"] - v["rate"] for v in rates]],
                    error_kw={"capsize": 2, "elinewidth": 0.8})
        if doors == "1":
            ax.axvline(GOAL, color="grey", linestyle="--", linewidth=1, label="goal")
        ax.set_xlim(0, 1)
        ax.set_title(f"from {doors} door{'s' if doors != '1' else ''}")
        ax.set_xlabel("success (95% Wilson CI)")
        ax.grid(axis="x", alpha=0.3)
    axes[0].set_yticks(y, [r["label"] for r in rows])
    axes[-1].legend(*axes[0].get_legend_handles_labels(), fontsize=8, loc="lower right")  # with the goal line
    fig.suptitle(f"Hop benchmark ({rows[0]['split']} episodes, n = {rows[0]['rates'][('1', '60')]['n']} per distance)")
    out.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(out, dpi=110)
    plt.close(fig)


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--run", type=parse_run, action="append", required=True,
                        help="LABEL=FOLDER[#AGENT]: a hop result folder and the agent shown (repeatable)")
    parser.add_argument("--out", required=True, help="PNG to write")
    args = parser.parse_args(argv)
    try:
        rows = load(args.run)
    except ValueError as err:
        parser.error(str(err))
    plot(rows, pathlib.Path(args.out))
    print("| run | agent | " + " | ".join(f"{d} door(s) ≤ {h}" for d in DOORS for h in HORIZONS) + " |")
    print("|---|---|" + "---|" * len(DOORS) * len(HORIZONS))
    for r in rows:
        cells = " | ".join(f"{100 * r['rates'][(d, h)]['rate']:.1f}" for d in DOORS for h in HORIZONS)
        print(f"| {r['label']} ({r['folder']}) | {r['agent']} | {cells} |")
    print(f"wrote {args.out}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
