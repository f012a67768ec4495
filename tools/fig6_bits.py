"""Which of the CNN classifier's errors move LEAPS (Fig. 6): the bits ablated against the ground truth.

``python tools/fig6_bits.py --source results/test_goalcont8_1000_v2 --out results/fig6_bits_v2_test``

With the paper's observation rule, LEAPS on the room classifier's bits (``leaps-cnn``) beats LEAPS on
the ground-truth bits (``leaps``) on the 1,000 test episodes, where the paper saw a small loss. The
classifier differs from the truth two ways: it turns bits on that the truth has off (false positives,
e.g. a room seen through a door) and leaves bits off, or turns them on late, that the truth has on
(misses). Two more agents separate them, each paired with both on the same episodes and seeds:
``leaps-cnn-and-truth`` keeps only the classifier's bits the truth confirms (no false positives) and
``leaps-cnn-or-truth`` adds the truth to them (no misses). The episodes are a seeded draw of
``--per-length`` of each plan length in ``--lengths`` from the source folder's episodes, so the source's
``leaps`` and ``leaps-cnn`` rows are reused, not re-run; the folder is resumable as any evaluation's.

With ``--fp-episodes K`` it then re-runs ``leaps-cnn`` on the first K of those episodes in this process,
counting the classifier's false positives and, for each, whether a room of that type lies one door from
the agent's room and whether it is the episode's target type (written to ``false_positives.json``).
"""

from __future__ import annotations

import argparse
import json
import pathlib
import sys

import numpy as np

from leaps_mj.evaluation import harness, stats
from leaps_mj.world import files, rooms

#: The agents compared: ground truth, the classifier, and the two ablations.
AGENTS = ("leaps", "leaps-cnn", "leaps-cnn-and-truth", "leaps-cnn-or-truth")
#: Agents whose rows the source folder holds.
REUSED = ("leaps", "leaps-cnn")
HORIZONS = (300, 500, 1000)


def subset(source_rows: list[dict], per_length: int, lengths, seed: int) -> list[int]:
    """A seeded draw of ``per_length`` episodes of each plan length in ``lengths``, sorted."""
    rng = np.random.default_rng(seed)
    chosen = []
    for length in lengths:
        pool = sorted(r["episode"] for r in source_rows if r["plan_length"] == length)
        if len(pool) < per_length:
            raise ValueError(f"plan length {length}: {len(pool)} episodes in the source, {per_length} asked for")
        chosen += rng.choice(pool, size=per_length, replace=False).tolist()
    return sorted(int(i) for i in chosen)


class FalsePositives:
    """An episode observer (:func:`leaps_mj.environment.episodes.run_episode`) counting the bits that are on
    where the ground truth has them off, and which of them name a neighbouring room's type or the target's."""

    def __init__(self):
        self.counts = {"steps": 0, "steps_with_false_positive": 0, "false_positives": 0, "neighbour_type": 0,
                       "target_type": 0, "target_type_next_door": 0}
        self._task = self._target = None
        self._near: dict[int, set[str]] = {}  # room id -> the types of the rooms one door from it

    def begin(self, env, spec, agent) -> None:
        del agent
        self._task, self._target = env.task, rooms.room_index(spec.target)
        house = env.task.house_model.house
        types = {room.id: room.type for room in house.rooms}
        self._near = {room.id: {types[r] for door in house.doors if room.id in door.rooms for r in door.rooms
                                if r != room.id} for room in house.rooms}

    def step(self, timestep, action, info) -> None:
        del action, info
        false = np.asarray(timestep.observation["semantic"], bool) & ~np.asarray(self._task.bits, bool)
        near = self._near.get(self._task.house_model.room_at(timestep.observation["pose"][:2]), set())
        c = self.counts
        c["steps"] += 1
        c["steps_with_false_positive"] += bool(false.any())
        for k in np.flatnonzero(false).tolist():
            c["false_positives"] += 1
            c["neighbour_type"] += rooms.ROOM_TYPES[k] in near
            c["target_type"] += k == self._target
            c["target_type_next_door"] += k == self._target and rooms.ROOM_TYPES[k] in near

    def end(self, result) -> None:
        del result


def false_positives(config: harness.EvalConfig, indices, rows: list[dict]) -> dict:
    """:class:`FalsePositives` counts of ``leaps-cnn`` (paper rule) run on ``indices`` as the harness runs it,
    and whether every episode took the steps its row in ``rows`` (the harness's run) records."""
    observer = FalsePositives()
    observed = harness.run_observed(config, harness.AGENTS["leaps-cnn"], indices, observer)
    recorded = {r["episode"]: (r["steps"], r["success_step"]) for r in rows}
    same = all((r["steps"], r["success_step"]) == recorded[r["episode"]] for r in observed)
    return {"episodes": len(indices), "same_as_evaluation": same, **observer.counts}


def main(argv=None) -> int:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--source", type=pathlib.Path, required=True,
                   help="an evaluation folder holding leaps and leaps-cnn rows")
    p.add_argument("--out", type=pathlib.Path, required=True, help="result folder (resumable)")
    p.add_argument("--per-length", type=int, default=60)
    p.add_argument("--lengths", type=int, nargs="+", default=[2, 3, 4, 5])
    p.add_argument("--workers", type=int, default=2)
    p.add_argument("--seed", type=int, default=0, help="seed of the episode draw")
    p.add_argument("--fp-episodes", type=int, default=0,
                   help="count the classifier's false positives on the first K episodes (0: skip)")
    args = p.parse_args(argv)
    try:
        config = harness.EvalConfig(**json.loads((args.source / "config.json").read_text()))
        source = {label: harness.read_rows(harness.csv_path(args.source, label)) for label in REUSED}
        for label, rows in source.items():
            if not rows:
                raise ValueError(f"{harness.csv_path(args.source, label)}: no rows; expected a finished {label} run")
        indices = subset(source["leaps"], args.per_length, args.lengths, args.seed)
        args.out.mkdir(parents=True, exist_ok=True)
        drawn = set(indices)
        for label, rows in source.items():
            path = harness.csv_path(args.out, label)
            if not path.exists():
                harness.append_rows(path, [r for r in rows if r["episode"] in drawn])
        table = harness.run(config, [harness.AGENTS[a] for a in AGENTS], indices, args.out, workers=args.workers)
    except ValueError as e:
        print(f"error: {e}", file=sys.stderr)
        return 2
    summary = harness.summarize(table, HORIZONS)
    paired = stats.paired_comparisons(table, HORIZONS, AGENTS[1:], ["leaps"])
    for label, per_base in stats.paired_comparisons(table, HORIZONS, AGENTS[2:], ["leaps-cnn"]).items():
        paired[label].update(per_base)
    text = harness.markdown(summary, HORIZONS, config, len(indices), paired)
    files.write_atomic(args.out / "results.md", text.encode())
    print(text)
    if args.fp_episodes:
        counts = false_positives(config, indices[:args.fp_episodes], table["leaps-cnn"])
        files.write_atomic(args.out / "false_positives.json", (json.dumps(counts, indent=1) + "\n").encode())
        print(json.dumps(counts, indent=1))
    return 0


if __name__ == "__main__":
    sys.exit(main())
