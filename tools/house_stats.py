#!/usr/bin/env python
"""Prints the semantic statistics of a house dataset against the reference (real homes).

    python tools/house_stats.py houses/roomnav-v1            # every split
    python tools/house_stats.py houses/roomnav-v1 --split train
    python tools/house_stats.py roomnav-v1 --markdown         # tables for the docs

Room-type frequencies per house, rooms per house, adjacency frequency per type
pair and its Spearman rank correlation with the LEAPS release's prior
(see leaps_mj/house_stats.py for the definitions).
"""

import argparse
import pathlib
import sys

sys.path.insert(0, str(pathlib.Path(__file__).resolve().parent.parent))

import leaps_mj  # noqa: E402,F401
from leaps_mj.world import dataset, houses  # noqa: E402
from leaps_mj.world import stats as house_stats


def main(argv=None) -> int:
    p = argparse.ArgumentParser(prog="house_stats.py", description=__doc__.split("\n\n")[0])
    p.add_argument("dataset", help="dataset folder, or a name under houses/ (e.g. roomnav-v1)")
    p.add_argument("--split", action="append", choices=dataset.SPLITS,
                   help="split(s) to include (repeatable; default: every split with houses)")
    p.add_argument("--top", type=int, default=12, help="strongest pairs to list (default %(default)s)")
    p.add_argument("--markdown", action="store_true", help="markdown tables")
    args = p.parse_args(argv)
    try:
        root = dataset.dataset_dir(args.dataset)
        splits = args.split or [s for s in dataset.SPLITS if any((root / s).glob("*.json"))]
        if not splits:
            raise ValueError(f"{str(root)!r} has no house files in any of {list(dataset.SPLITS)}")
        paths = [path for s in splits for path in dataset.list_houses(root, s)]
        stats = house_stats.compute(houses.House.load(path) for path in paths)
    except ValueError as e:
        print(f"house_stats.py: error: {e}", file=sys.stderr)
        return 1
    print(f"Dataset {root} (splits: {', '.join(splits)})")
    print(house_stats.format_report(stats, top=args.top, markdown=args.markdown))
    return 0


if __name__ == "__main__":
    sys.exit(main())
