"""Hop success against training samples: several hop-benchmark results on one plot.

``python tools/hop_curve.py --run "same recipe=108000=results/hops_shipped_v2_test" ... --out docs/img/hop_curve.png``

Each ``--run LABEL=SAMPLES=FOLDER`` names a result folder of
``python -m leaps_mj.evaluation.hops`` (its ``summary.json``), the training
samples per target of the sub-policies it measured, and a label; runs with the
same label are joined by a line (one recipe trained on), the others stand
alone. The four panels show the ``pure`` success within 30 and 60 steps from 1
and 2 doors with 95 % Wilson intervals, so a plateau or a gain is read off at
a glance instead of from several tables. All folders must be hop runs of one
dataset, split and seed (the same episodes); the tool prints the plotted
numbers as a table.
"""

from __future__ import annotations

import argparse
import json
import pathlib
import sys

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402  (after the backend is chosen)

PANELS = (("1", "30"), ("1", "60"), ("2", "30"), ("2", "60"))
#: Issue 13's goal for the sub-policies: 80 % of the one-door hops within 60 steps.
GOAL = (("1", "60"), 0.8)


def _doors(d: str) -> str:
    return "1 door" if d == "1" else f"{d} doors"


def parse_run(text: str) -> tuple[str, int, pathlib.Path]:
    """``LABEL=SAMPLES=FOLDER`` → (label, samples, folder); a clear error otherwise."""
    parts = text.split("=")
    if len(parts) != 3 or not parts[0] or not parts[1].isdigit() or int(parts[1]) < 1:
        raise argparse.ArgumentTypeError(f"--run {text!r}: expected LABEL=SAMPLES=FOLDER with SAMPLES a positive "
                                         "integer (training samples per target)")
    folder = pathlib.Path(parts[2])
    if not (folder / "summary.json").is_file():
        raise argparse.ArgumentTypeError(f"--run {text!r}: {str(folder)!r} holds no summary.json; expected a "
                                         "result folder of python -m leaps_mj.evaluation.hops")
    return parts[0], int(parts[1]), folder


def load(runs: list[tuple[str, int, pathlib.Path]]) -> list[dict]:
    """One row per run: label, samples and the ``pure`` rates of :data:`PANELS`.

    Raises:
      ValueError: if the folders are not hop runs of one dataset, split and seed.
    """
    rows, first = [], None
    for label, samples, folder in runs:
        doc = json.loads((folder / "summary.json").read_text())
        cfg = doc["config"]
        key = {k: cfg.get(k) for k in ("dataset", "split", "seed", "episodes")}
        if key["episodes"] != "hops" or "pure" not in doc["success"]:
            raise ValueError(f"{str(folder)!r}: not a hop benchmark run of the pure sub-policy ({key})")
        if first is not None and key != first[1]:
            raise ValueError(f"{str(folder)!r} ran other episodes ({key}) than {str(first[0])!r} ({first[1]})")
        first = first or (folder, key)
        success = doc["success"]["pure"]
        rows.append({"label": label, "samples": samples, "folder": str(folder), "split": key["split"],
                     "rates": {p: success[p[1]][p[0]]["all"] for p in PANELS}})
    return rows


def plot(rows: list[dict], out: pathlib.Path) -> None:
    """Four panels (1 / 2 doors × ≤ 30 / ≤ 60 steps), success against samples per target."""
    fig, axes = plt.subplots(2, 2, figsize=(10, 7), sharex=True, layout="constrained")
    labels = list(dict.fromkeys(r["label"] for r in rows))
    colours = plt.rcParams["axes.prop_cycle"].by_key()["color"]
    for ax, panel in zip(axes.ravel(), PANELS):
        for k, label in enumerate(labels):
            own = sorted((r for r in rows if r["label"] == label), key=lambda r: r["samples"])
            # a lone point moves a little sideways by its label, so runs of one size stay apart
            x = [r["samples"] / 1000 + (0 if len(own) > 1 else 3 * k) for r in own]
            rates = [r["rates"][panel] for r in own]
            y = [v["rate"] for v in rates]
            err = [[v["rate"] - v["low"] for v in rates], [v["high"] - v["rate"] for v in rates]]
            ax.errorbar(x, y, yerr=err, fmt="o-" if len(own) > 1 else "s", color=colours[k % len(colours)],
                        capsize=3, label=label)
        if panel == GOAL[0]:
            ax.axhline(GOAL[1], color="grey", linestyle="--", linewidth=1, label="goal")
        ax.set_title(f"from {_doors(panel[0])}, within {panel[1]} steps")
        ax.set_ylim(0, 1)
        ax.grid(alpha=0.3)
    for ax in axes[1]:
        ax.set_xlabel("training samples per target (thousands)")
    for ax in axes[:, 0]:
        ax.set_ylabel("success (95% Wilson CI)")
    axes[0, 1].legend(fontsize=8)
    fig.suptitle(f"Hop benchmark ({rows[0]['split']} episodes): success against training samples")
    out.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(out, dpi=110)
    plt.close(fig)


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--run", type=parse_run, action="append", required=True,
                        help="LABEL=SAMPLES=FOLDER: a hop result folder and its samples per target (repeatable)")
    parser.add_argument("--out", required=True, help="PNG to write")
    args = parser.parse_args(argv)
    try:
        rows = load(args.run)
    except ValueError as err:
        parser.error(str(err))
    plot(rows, pathlib.Path(args.out))
    print("| run | samples per target | " + " | ".join(f"{_doors(d)} ≤ {h}" for d, h in PANELS) + " |")
    print("|---|---:|" + "---|" * len(PANELS))
    for r in rows:
        cells = " | ".join(f"{100 * r['rates'][p]['rate']:.1f}" for p in PANELS)
        print(f"| {r['label']} ({r['folder']}) | {r['samples']:,} | {cells} |")
    print(f"wrote {args.out}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
