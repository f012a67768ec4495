"""Writes the fixed evaluation episodes of a dataset (stratified by plan length).

    python tools/make_episodes.py                       # roomnav-v1: valid (100/length) and test (500/length)
    python tools/make_episodes.py --split test --per-length 500 --seed 0
"""

import argparse
import sys
import time

from leaps_mj.environment import episodes


def main(argv=None) -> int:
    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--dataset", default="roomnav-v1", help="dataset name under houses/ or a folder")
    p.add_argument("--split", choices=["valid", "test"], action="append",
                   help="split(s) to write (default: valid and test)")
    p.add_argument("--per-length", type=int, default=None,
                   help="episodes per plan length 1..5 (default: 100 for valid, 500 for test)")
    p.add_argument("--seed", type=int, default=0)
    args = p.parse_args(argv)
    if args.per_length is not None and args.per_length < 1:
        p.error(f"--per-length {args.per_length}: expected a positive integer")
    for split in args.split or ["valid", "test"]:
        t0 = time.time()
        n = args.per_length or (500 if split == "test" else 100)
        eps, counts = episodes.generate(args.dataset, split, per_length=n, seed=args.seed)
        path = episodes.episodes_path(args.dataset, split)
        episodes.write(path, eps)
        missing = [k for k, v in counts.items() if v == 0]
        print(f"{split}: {len(eps)} episodes -> {path} in {time.time() - t0:.1f} s; per plan length {counts}"
              + (f"; no house offers plan lengths {missing}" if missing else ""))
    return 0


if __name__ == "__main__":
    sys.exit(main())
