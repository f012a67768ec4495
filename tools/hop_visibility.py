"""Hop success split by whether the target can be seen from the start by turning on the spot.

``python tools/hop_visibility.py --dataset roomnav-v2 --split test FOLDER [FOLDER ...]``

For every one-door hop episode (``--distance`` to change) it turns the camera through a full circle
at the start position (12 headings, 30° apart, nothing else moves) and notes whether any see-object
of the target's type (the pixels the see test counts) comes into view. Then, for each hop result
folder given (written by ``python -m leaps_mj.evaluation.hops``, on the same dataset and split), it
prints each agent's success within ``--horizon`` steps on the episodes where the target comes into
view, where it does not, and where the target has no see-objects (``outdoor``, ``indoor``), with 95 %
Wilson intervals. A learner that perceives the target but cannot act on it fails the first group; one
that does not explore fails the second.
"""

from __future__ import annotations

import argparse
import json
import math
import pathlib
import sys

import numpy as np

from leaps_mj.environment import episodes as episodes_lib
from leaps_mj.environment import roomnav
from leaps_mj.evaluation import harness, stats
from leaps_mj.world import rooms

#: Headings of the look around, evenly spaced from the start heading.
HEADINGS = 12
#: Groups of episodes, in the printed order.
GROUPS = ("target comes into view", "target never in view", "no see-objects")


def in_view_on_turning(env, spec) -> bool:
    """Whether a see-object of ``spec.target``'s type shows in a full turn at the start position."""
    env.reset_to(spec)
    physics, mask = env.physics, env.segment_luts[1][rooms.room_index(spec.target)]
    x, y, yaw = spec.start
    for k in range(HEADINGS):
        physics.set_agent_pose(np.array([x, y, yaw + 2 * math.pi * k / HEADINGS]))
        physics.forward_kinematics()
        segments, _ = env.renderer.render_segments(physics.data.ptr)
        if mask.take(segments).any():
            return True
    return False


def groups(dataset: str, split: str, distance: int) -> dict[int, str]:
    """Episode index (in the split's hop file) -> its group, for the hops ``distance`` doors away."""
    specs = episodes_lib.load_split(dataset, split, "hops")
    env = roomnav.load(dataset, split, width=40, height=30)
    try:
        return {i: (GROUPS[2] if not rooms.SEE_OBJECTS.get(s.target)
                    else GROUPS[0] if in_view_on_turning(env, s) else GROUPS[1])
                for i, s in enumerate(specs) if s.plan_length == distance}
    finally:
        env.close()


def _check_folder(folder: pathlib.Path, dataset: str, split: str) -> list[pathlib.Path]:
    """The folder's per-agent CSVs, after checking that it ran this split's hop episodes."""
    config_path = folder / "config.json"
    if not config_path.is_file():
        raise ValueError(f"{str(folder)!r} holds no config.json: expected a folder written by "
                         "python -m leaps_mj.evaluation.hops")
    config = json.loads(config_path.read_text())
    ran = (pathlib.Path(str(config.get("dataset"))).name, config.get("split"), config.get("episodes"))
    if ran != (pathlib.Path(dataset).name, split, "hops"):
        raise ValueError(f"{str(folder)!r} ran {ran}; expected the hop episodes of {dataset} / {split}")
    return sorted(folder.glob("episodes_*.csv"))


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("folders", nargs="+", help="hop result folders (python -m leaps_mj.evaluation.hops --out)")
    parser.add_argument("--dataset", default="roomnav-v2")
    parser.add_argument("--split", default="test")
    parser.add_argument("--distance", type=int, default=1, help="doors from the target (1 or 2)")
    parser.add_argument("--horizon", type=int, default=60, help="success within this many steps")
    args = parser.parse_args(argv)
    if args.distance not in episodes_lib.HOP_DISTANCES or args.horizon < 1:
        parser.error(f"--distance {args.distance}, --horizon {args.horizon}: expected a distance in "
                     f"{list(episodes_lib.HOP_DISTANCES)} and a positive horizon")
    try:
        csvs = [(folder, path) for folder in map(pathlib.Path, args.folders)
                for path in _check_folder(folder, args.dataset, args.split)]
        group_of = groups(args.dataset, args.split, args.distance)
    except ValueError as e:
        print(f"error: {e}", file=sys.stderr)
        return 2
    sizes = {g: sum(v == g for v in group_of.values()) for g in GROUPS}
    print(f"{len(group_of)} hop episodes {args.distance} door(s) away ({args.dataset} / {args.split}); "
          f"success within {args.horizon} steps\n")
    print("| run | agent | " + " | ".join(f"{g} (n = {sizes[g]})" for g in GROUPS) + " |")
    print("|---|---|" + "---|" * len(GROUPS))
    for folder, path in csvs:
        rows = [r for r in harness.read_rows(path) if int(r["episode"]) in group_of]
        ok = stats.success_at(rows, args.horizon)
        of = np.array([group_of[int(r["episode"])] for r in rows])
        cells = []
        for g in GROUPS:
            k, n = int(ok[of == g].sum()), int((of == g).sum())
            low, high = stats.wilson(k, n)
            cells.append(f"{100 * k / n:.1f}% [{100 * low:.1f}, {100 * high:.1f}]" if n else "–")
        agent = path.stem.removeprefix("episodes_")
        print(f"| {folder} | {agent} | " + " | ".join(cells) + " |")
    return 0


if __name__ == "__main__":
    sys.exit(main())
