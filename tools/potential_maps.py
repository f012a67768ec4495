"""What map-goal networks with a potential head predict, beside the teacher's potential labels.

``python tools/potential_maps.py --data runs/goal_P/data/round_011.npz --net "linear=runs/goal_P/goal.pt"
--net "conv=runs/goal_PC/goal.pt" --out docs/img/potential_maps.png``

Reads a round of a ``python -m leaps_mj.train goal --potential true`` run's aggregated dataset
(``data/round_<k>.npz``: maps, node, goal label, potential labels) and draws, for a few samples
drawn with ``--seed``, the egocentric map, the potential labels
(:meth:`leaps_mj.environment.goal_teacher.TeacherGoals.labels`) and each network's predicted
potential, in metres, with the teacher's goal cell (red star), the agent (blue dot) and where each
network's goal would be (white cross: the walk down the potential,
:func:`leaps_mj.environment.goal_teacher.potential_goal`). It prints, per network, the mean
absolute error of the potential over the samples of that round, and how often the walk down the
prediction ends within 1.5 m of the teacher's goal (on the labels themselves, for reference).
"""

from __future__ import annotations

import argparse
import pathlib
import sys

import matplotlib
import numpy as np
import torch

sys.path.insert(0, str(pathlib.Path(__file__).resolve().parent.parent))

from leaps_mj.environment import goal_teacher, mapping  # noqa: E402
from leaps_mj.learning import goal_policy, train_goal  # noqa: E402
from leaps_mj.world import rooms  # noqa: E402

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402  (after the backend is chosen)

#: Window cells (1.5 m) within which a goal counts as the teacher's.
NEAR = 6


def parse_net(text: str) -> tuple[str, pathlib.Path]:
    """``LABEL=PATH`` -> (label, path of a goal.pt with a potential head); a clear error otherwise."""
    label, sep, path = text.partition("=")
    if not sep or not label or not path:
        raise argparse.ArgumentTypeError(f"--net {text!r}: expected LABEL=PATH (e.g. linear=runs/goal_P/goal.pt)")
    return label, pathlib.Path(path)


def near_teacher(potentials: np.ndarray, labels: np.ndarray) -> float:
    """Share of samples whose walk down ``potentials`` (N, WINDOW ** 2) ends within :data:`NEAR` cells of
    the teacher's goal cell (N,)."""
    ends = np.array([goal_teacher.potential_goal(p) for p in potentials])
    rows, cols = np.divmod(ends, mapping.WINDOW)
    goal_rows, goal_cols = np.divmod(labels, mapping.WINDOW)
    return float(np.mean(np.hypot(rows - goal_rows, cols - goal_cols) <= NEAR))


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--data", type=pathlib.Path, required=True, help="a round_<k>.npz of a --potential true run")
    parser.add_argument("--net", type=parse_net, action="append", required=True, help="LABEL=PATH of a goal.pt")
    parser.add_argument("--samples", type=int, default=4, help="samples drawn")
    parser.add_argument("--seed", type=int, default=0)
    parser.add_argument("--out", type=pathlib.Path, required=True, help="PNG written")
    args = parser.parse_args(argv)
    data = np.load(args.data)
    if "potential" not in data:
        parser.error(f"--data {args.data}: holds no potential labels; expected a round of a --potential true run")
    nets = []
    for label, path in args.net:
        net, _ = goal_policy.load_goal_net(path)
        if not net.config.potential:
            parser.error(f"--net {label}={path}: a network without a potential head")
        nets.append((label, net))
    truth = data["potential"].reshape(len(data["label"]), -1).astype(np.float32) * mapping.CELL
    print(f"{len(truth)} samples of {args.data}")
    print(f"| potential | mean abs. error (m) | walk ends within {NEAR * mapping.CELL} m of the teacher's goal |")
    print("|---|---|---|")
    print(f"| labels | 0 | {near_teacher(truth, data['label']):.3f} |")
    predicted = {}
    for label, net in nets:
        outputs = []
        with torch.no_grad():
            for start in range(0, len(truth), 1024):
                maps = train_goal.unpack_maps(data["maps"][start:start + 1024], net.config.input_channels)
                bits = torch.as_tensor(data["bits"][start:start + 1024]) if net.config.room_bits else None
                outputs.append(net.heads(maps, torch.as_tensor(data["node"][start:start + 1024]), bits)[1].numpy())
        predicted[label] = np.concatenate(outputs)
        error = float(np.abs(predicted[label] - truth).mean())
        print(f"| {label} | {error:.2f} | {near_teacher(predicted[label], data['label']):.3f} |")

    rng = np.random.default_rng(args.seed)
    chosen = np.sort(rng.choice(len(truth), args.samples, replace=False))
    low, high = goal_teacher.POTENTIAL_RANGE
    fig, axes = plt.subplots(2 + len(nets), args.samples, figsize=(3 * args.samples, 3 * (2 + len(nets))),
                             squeeze=False)
    channels = mapping.CHANNELS
    for k, i in enumerate(chosen):
        window = train_goal.unpack_maps(data["maps"][i:i + 1], len(channels))[0].numpy()
        shade = (2 * window[channels.index("obstacle")] + window[channels.index("floor")]
                 + 3 * window[channels.index("door")])
        axes[0, k].imshow(shade, cmap="gray")
        axes[0, k].set_title(f"map, {rooms.GRAPH_NODES[int(data['node'][i])]}", fontsize=9)
        panels = [("labels", truth[i])] + [(label, predicted[label][i]) for label, _ in nets]
        for row, (label, values) in enumerate(panels, start=1):
            axes[row, k].imshow(values.reshape(mapping.WINDOW, mapping.WINDOW), vmin=low, vmax=high, cmap="viridis")
            axes[row, k].set_title(f"potential: {label} (m)", fontsize=9)
            end_row, end_col = divmod(goal_teacher.potential_goal(values), mapping.WINDOW)
            axes[row, k].plot(end_col, end_row, "wx", markersize=9, mew=2)
        goal_row, goal_col = divmod(int(data["label"][i]), mapping.WINDOW)
        for ax in axes[:, k]:
            ax.plot(goal_col, goal_row, "r*", markersize=9)
            ax.plot(mapping.WINDOW / 2 - 0.5, mapping.WINDOW / 2 - 0.5, "bo", markersize=5)
            ax.set_xticks([])
            ax.set_yticks([])
    fig.suptitle("ahead is up; red star: teacher's goal; white cross: end of the walk down the potential", fontsize=10)
    fig.tight_layout()
    args.out.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(args.out, dpi=90)
    print(f"wrote {args.out}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
