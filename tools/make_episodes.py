"""Writes the fixed evaluation episodes of a dataset (stratified by plan length), or its hop episodes.

    python tools/make_episodes.py                       # the canonical dataset: valid (100/length) and test (500/length)
    python tools/make_episodes.py --split test --per-length 500 --seed 0
    python tools/make_episodes.py --hops                # hops_{valid,test}.jsonl: 20 / 30 starts per node and door distance
    python tools/make_episodes.py --hops --dataset roomnav-v2 --split test --per-node 30
    python tools/make_episodes.py --hops --large        # hops_large_{valid,test}.jsonl: 100 starts each, another draw
"""

import argparse
import sys
import time

from leaps_mj.environment import episodes
from leaps_mj.world import dataset


def main(argv=None) -> int:
    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--dataset", default=dataset.CANONICAL,
                   help="dataset name under houses/ or a folder (default %(default)s)")
    p.add_argument("--split", choices=["valid", "test"], action="append",
                   help="split(s) to write (default: valid and test)")
    p.add_argument("--per-length", type=int, default=None,
                   help="episodes per plan length 1..5 (default: 100 for valid, 500 for test)")
    p.add_argument("--hops", action="store_true",
                   help="write the hop episodes (starts 1 and 2 doors from every graph node) instead")
    p.add_argument("--per-node", type=int, default=None,
                   help="with --hops: starts per node and door distance (default: 20 for valid, 30 for test; "
                        "100 with --large)")
    p.add_argument("--large", action="store_true",
                   help="with --hops: the large hop set (hops_large_<split>.jsonl), an independent draw")
    p.add_argument("--seed", type=int, default=None,
                   help="seed of the draws (default: 0; 1 for the large hop set)")
    args = p.parse_args(argv)
    for flag, value in (("--per-length", args.per_length), ("--per-node", args.per_node)):
        if value is not None and value < 1:
            p.error(f"{flag} {value}: expected a positive integer")
    if (args.per_node is not None or args.large) and not args.hops:
        p.error("--per-node and --large need --hops")
    kind = ("hops_large" if args.large else "hops") if args.hops else "plan_length"
    for split in args.split or ["valid", "test"]:
        t0 = time.time()
        if args.hops:
            quotas, seed = episodes.HOP_SETS[kind]
            n = args.per_node or quotas[split]
            eps, counts = episodes.generate_hops(args.dataset, split, per_node=n,
                                                 seed=seed if args.seed is None else args.seed)
            summary = "; ".join(f"{node} " + " / ".join(f"{c['episodes']} in {c['houses']} houses"
                                                        for c in per_d.values()) for node, per_d in counts.items())
            note = f"per node (1 / 2 doors): {summary}"
        else:
            n = args.per_length or (500 if split == "test" else 100)
            eps, counts = episodes.generate(args.dataset, split, per_length=n, seed=args.seed or 0)
            missing = [k for k, v in counts.items() if v == 0]
            note = f"per plan length {counts}" + (f"; no house offers plan lengths {missing}" if missing else "")
        path = episodes.episodes_path(args.dataset, split, kind)
        episodes.write(path, eps)
        print(f"{split}: {len(eps)} episodes -> {path} in {time.time() - t0:.1f} s; {note}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
