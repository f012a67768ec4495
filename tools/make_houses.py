#!/usr/bin/env python
"""Generates a RoomNav-MJ house dataset: MJCF + metadata per house, and a manifest.

    python tools/make_houses.py                      # the canonical houses/roomnav-v2 (200/30/100, seed 0)
    python tools/make_houses.py --out /tmp/h --train 10 --valid 0 --test 5 --seed 3 --preview

Writes DIR/{train,valid,test}/<id>.xml + <id>.json, DIR/manifest.json (sha256 of
every house file) and, with --preview [SPLIT ...], DIR/preview/<id>.png for the
houses of those splits (all splits when none is named; the canonical dataset
ships the test split's). Same arguments, same bytes.
"""

import argparse
import pathlib
import sys
import time

sys.path.insert(0, str(pathlib.Path(__file__).resolve().parent.parent))

import leaps_mj  # noqa: E402,F401  (sets MUJOCO_GL before anything imports dm_control)
from leaps_mj.world import dataset  # noqa: E402


def _int_at_least(minimum: int, what: str):
    """An argparse type: an integer >= ``minimum``, with an error naming the value."""

    def parse(text: str) -> int:
        try:
            n = int(text)
        except ValueError:
            raise argparse.ArgumentTypeError(f"expected a {what} integer, got {text!r}") from None
        if n < minimum:
            raise argparse.ArgumentTypeError(f"expected a {what} integer, got {n}")
        return n

    return parse


_count = _int_at_least(0, "non-negative")
_positive = _int_at_least(1, "positive")


def parse_args(argv=None) -> argparse.Namespace:
    canon = dataset.CANONICAL_COUNTS
    p = argparse.ArgumentParser(
        prog="make_houses.py",
        description="Generate a RoomNav-MJ house dataset (defaults: the canonical "
                    f"{dataset.CANONICAL} set).",
    )
    p.add_argument("--out", type=pathlib.Path, default=dataset.HOUSES_DIR / dataset.CANONICAL,
                   help="output folder (default: houses/%(default)s relative to the repository)".replace(
                       "%(default)s", dataset.CANONICAL))
    p.add_argument("--train", type=_count, default=canon["train"], help="training houses (default %(default)s)")
    p.add_argument("--valid", type=_count, default=canon["valid"], help="validation houses (default %(default)s)")
    p.add_argument("--test", type=_count, default=canon["test"], help="test houses (default %(default)s)")
    p.add_argument("--seed", type=_count, default=dataset.CANONICAL_SEED, help="dataset seed (default %(default)s)")
    p.add_argument("--name", default=None, help="dataset name in the manifest (default: the folder name)")
    p.add_argument("--preview", nargs="*", choices=dataset.SPLITS, metavar="SPLIT",
                   help="also write a top-down PNG per house of these splits (default: none; "
                        "no SPLIT: every split) under DIR/preview/")
    p.add_argument("--workers", type=_positive, default=1, help="generator processes (default %(default)s)")
    p.add_argument("--quiet", action="store_true", help="no progress bar")
    args = p.parse_args(argv)
    if args.train == args.valid == args.test == 0:
        p.error("--train, --valid and --test are all 0: nothing to generate")
    if args.out.exists() and not args.out.is_dir():
        p.error(f"--out {str(args.out)!r} exists and is not a directory")
    for parent in args.out.parents:
        if parent.exists():
            if not parent.is_dir():
                p.error(f"--out {str(args.out)!r}: {str(parent)!r} is not a directory")
            break
    return args


def _preview_splits(value: list[str] | None) -> tuple[str, ...]:
    """The splits to preview: ``--preview`` absent → none, bare → all, else the named ones."""
    if value is None:
        return ()
    return tuple(value) or dataset.SPLITS


def main(argv=None) -> int:
    args = parse_args(argv)
    start = time.perf_counter()
    try:
        manifest = dataset.write_dataset(
            args.out, {"train": args.train, "valid": args.valid, "test": args.test}, seed=args.seed,
            name=args.name, preview=_preview_splits(args.preview), workers=args.workers, progress=not args.quiet,
            log=lambda m: print(m, file=sys.stderr),
        )
    except (OSError, ValueError, RuntimeError) as e:
        print(f"make_houses.py: error: {e}", file=sys.stderr)
        return 1
    n = sum(manifest["generator"]["counts"].values())
    print(f"wrote {n} houses ({len(manifest['files'])} files) and {args.out / dataset.MANIFEST} "
          f"in {time.perf_counter() - start:.1f} s")
    return 0


if __name__ == "__main__":
    sys.exit(main())
