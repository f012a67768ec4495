"""Records the example LEAPS episode shipped in ``examples/`` and its picture.

Runs the LEAPS agent (local-expert sub-policy) on the fixed test episodes of
a dataset, in file order, and keeps the first episode that shows what a record
is for: a success, at least ``--min-subtargets`` sub-targets (the agent
replanned), at most ``--max-steps`` steps (a small file). Writes

* ``examples/leaps_episode.mcap``: the record (open it in Foxglove), and
* ``docs/img/record_preview.png``: top-down trajectory + first-person views.

    python examples/make_example_record.py [--dataset roomnav-v1] [--prior cpu]
"""

from __future__ import annotations

import argparse
import pathlib
import shutil
import sys
import tempfile

import leaps_mj
from leaps_mj.environment import episodes
from leaps_mj.evaluation import registry
from leaps_mj.planning import agents
from leaps_mj.records import recorder as record
from leaps_mj.records import replay

ROOT = pathlib.Path(__file__).resolve().parent.parent


def main(argv=None) -> int:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("--dataset", default="roomnav-v1")
    p.add_argument("--split", default="test")
    p.add_argument("--prior", default="cpu", help="LEAPS prior (see leaps_mj.planning.agents.load_model)")
    p.add_argument("--min-plan-length", type=int, default=3)
    p.add_argument("--min-subtargets", type=int, default=3)
    p.add_argument("--max-steps", type=int, default=200)
    p.add_argument("--tries", type=int, default=60, help="episodes to try before giving up")
    p.add_argument("--seed", type=int, default=0)
    p.add_argument("--out", type=pathlib.Path, default=ROOT / "examples" / "leaps_episode.mcap")
    p.add_argument("--preview", type=pathlib.Path, default=ROOT / "docs" / "img" / "record_preview.png")
    args = p.parse_args(argv)

    env = leaps_mj.load(args.dataset, args.split, seed=args.seed, reward="sparse", horizon=args.max_steps)
    try:
        return _record(env, args)
    finally:
        env.close()


def _record(env, args) -> int:
    model = agents.load_model(args.prior)
    specs = [s for s in episodes.load_split(args.dataset, args.split) if (s.plan_length or 0) >= args.min_plan_length]
    run_config = {"dataset": args.dataset, "split": args.split, "agent": "leaps", "subpolicy": "local",
                  "prior": args.prior, "horizon": args.max_steps, "seed": args.seed}
    with tempfile.TemporaryDirectory() as tmp:
        for i, spec in enumerate(specs[: args.tries]):
            agent = registry.make_agent("leaps", env, seed=args.seed, model=model)
            path = pathlib.Path(tmp) / f"{i}.mcap"
            with record.EpisodeRecorder(path, env, run_config={**run_config, "episode": spec.to_json()}) as rec:
                result = episodes.run_episode(env, agent, spec, args.max_steps, observer=rec)
            subtargets = replay.load(path).outcome["subtargets"]
            print(f"{spec.house} -> {spec.target} (plan length {spec.plan_length}): success={result['success']} "
                  f"steps={result['steps']} sub-targets={subtargets}")
            if result["success"] and len(subtargets) >= args.min_subtargets:
                args.out.parent.mkdir(parents=True, exist_ok=True)
                shutil.copyfile(path, args.out)
                break
        else:
            print(f"no episode of the first {args.tries} qualifies; relax --max-steps or --min-subtargets",
                  file=sys.stderr)
            return 1
    rec = replay.load(args.out)
    replay.save_preview(rec, args.preview)
    print(replay.summary(rec))
    print(f"wrote {args.out} ({args.out.stat().st_size / 1024:.0f} KiB) and {args.preview}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
