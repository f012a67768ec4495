"""Learn the room-connectivity prior by random exploration (the paper's Sec. 4.1).

``python -m leaps_mj.train prior --preset cpu --out runs/prior_cpu``

For every training house and every node of the semantic graph present in it
(its room types, plus ``indoor`` when it has untyped indoor space), the agent
starts ``trials`` times at a uniformly drawn free cell of a room of that type,
with a uniform heading, and takes ``steps`` uniformly random actions in the
blind (pixel-free) environment. A run from node i is one trial of every pair
(i, j) with j present in the house, and a positive when the agent was in j
during the run (from the semantic bits; all bits off is ``indoor``). The prior
is the maximum-likelihood fraction of positives pooled over both orders of a
pair, clipped to [1e-4, 1 - 1e-4] (:func:`leaps_mj.planning.semantic.learn_prior`).
Pairs are counted only in houses where both nodes are present, so the prior is
P(connected | both present), as in the paper.

Houses are explored by worker processes (``--workers``), or by Ray actors
across a cluster (``--backend ray [--ray-address ADDR] [--num-workers N]``,
:mod:`leaps_mj.learning.ray_prior`), in the split's order; every house's runs
are seeded by the house alone, so both backends count the same. The pooled
counts are checkpointed atomically to ``<out>/state.json`` after every house
(:mod:`leaps_mj.learning.trainer`), so an interrupted run resumes where it
stopped, and a run under other settings in the same folder is refused. Outputs: ``<out>/prior.json`` (a
:class:`leaps_mj.planning.semantic.SemanticModel` with the paper's observation noise),
``<out>/prior.png`` (the paper's Fig. 2), and the Spearman rank correlation
with the original release's SUNCG prior, printed.
"""

from __future__ import annotations

import argparse
import contextlib
import dataclasses
import math
import multiprocessing
import os
import pathlib
import sys
import time
import zlib

import numpy as np

from leaps_mj.environment import roomnav
from leaps_mj.environment.roomnav import EpisodeSpec
from leaps_mj.learning import backend_options
from leaps_mj.learning import trainer as trainer_lib
from leaps_mj.planning import semantic
from leaps_mj.world import dataset as dataset_lib
from leaps_mj.world import rooms

N = semantic.NUM_NODES


@dataclasses.dataclass(frozen=True)
class PriorConfig:
    """Settings of prior learning.

    Attributes:
      dataset: dataset name under ``houses/`` or a folder.
      split: split whose houses are explored.
      houses: explore only the first this many houses of the split (None: all).
      trials: random runs per present node per house (paper: 25-50).
      steps: random actions per run (paper: 300).
      floor: clip bound of the MLE (paper: 1e-4).
      seed: base seed; house h uses ``SeedSequence([seed, crc32(h)])``.
    """

    dataset: str = dataset_lib.CANONICAL
    split: str = "train"
    houses: int | None = None
    trials: int = 10
    steps: int = 300
    floor: float = 1e-4
    seed: int = 0

    def __post_init__(self):
        for name in ("trials", "steps"):
            value = getattr(self, name)
            if isinstance(value, bool) or not isinstance(value, int) or value < 1:
                raise ValueError(f"{name} {value!r}: expected a positive integer")
        if self.houses is not None and (not isinstance(self.houses, int) or self.houses < 1):
            raise ValueError(f"houses {self.houses!r}: expected a positive integer or None (all)")
        if not 0.0 < self.floor < 0.5:
            raise ValueError(f"floor {self.floor!r}: expected a number in (0, 0.5)")


PRESETS = {
    "tiny": PriorConfig(houses=3, trials=2),
    "cpu": PriorConfig(trials=10),
    "paper": PriorConfig(trials=50),
}


def house_seed(seed: int, house_id: str) -> int:
    """Seed of one house's runs: independent of which other houses are explored."""
    return int(np.random.SeedSequence([seed, zlib.crc32(house_id.encode())]).generate_state(1)[0])


def present_nodes(house) -> list[int]:
    """Graph nodes a house has rooms of (``indoor`` for untyped indoor space), sorted."""
    return sorted({rooms.room_index(t) for t in house.room_types})


def count_run(pos: np.ndarray, trials: np.ndarray, start: int, present: list[int], seen) -> None:
    """Adds one run from node ``start`` to the counts (in place).

    Args:
      pos: (9, 9) positives; ``pos[start, j]`` grows when j was seen.
      trials: (9, 9) trials; ``trials[start, j]`` grows for every present j.
      start: the node the run started in.
      present: the nodes present in the house.
      seen: 9 bools, the nodes the run visited (:func:`leaps_mj.planning.semantic.seen_vector`).
    """
    for j in present:
        if j != start:
            trials[start, j] += 1
            pos[start, j] += bool(seen[j])


def explore_house(env, house_id: str, config: PriorConfig) -> tuple[np.ndarray, np.ndarray]:
    """Random-exploration counts of one house.

    Args:
      env: a blind :class:`leaps_mj.environment.roomnav.RoomNavEnvironment` over the split,
        with ``horizon >= config.steps``.
      house_id: the house.
      config: trials, steps and seed.

    Returns:
      (positives, trials), two (9, 9) int arrays indexed [start node, other node].
    """
    hm = env.house_model(house_id)
    rng = np.random.default_rng(house_seed(config.seed, house_id))
    present = present_nodes(hm.house)
    # Any target the blind env cannot declare reached: not outdoor (a see-test room).
    target = next((t for t in hm.house.room_types if t not in ("outdoor", rooms.INDOOR)), None)
    if target is None:
        raise ValueError(f"house {house_id!r} has no indoor room of a target type; cannot start episodes")
    pos = np.zeros((N, N), dtype=np.int64)
    trials = np.zeros((N, N), dtype=np.int64)
    for start in present:
        ids = [r.id for r in hm.house.rooms if rooms.room_index(r.type) == start]
        cells = np.flatnonzero((hm.grid.free & np.isin(hm.grid.room_id, ids)).ravel())
        if cells.size == 0:
            raise ValueError(f"house {house_id!r}: no reachable floor in rooms of type {rooms.GRAPH_NODES[start]!r}")
        for _ in range(config.trials):
            xy = hm.grid.to_world(np.unravel_index(rng.choice(cells), hm.grid.shape))
            spec = EpisodeSpec(house_id, (float(xy[0]), float(xy[1]), float(rng.uniform(-math.pi, math.pi))),
                               target)
            ts = env.reset_to(spec)
            bits = [ts.observation["semantic"]]
            for action in rng.integers(rooms.NUM_ACTIONS, size=config.steps):
                ts = env.step(int(action))
                bits.append(ts.observation["semantic"])
                if ts.last():
                    break
            count_run(pos, trials, start, present, semantic.seen_vector(np.stack(bits)))
    return pos, trials


class HouseExplorer:
    """Explores houses with one blind environment over the split: a worker process's, or a Ray actor's.

    Args:
      config: the run's settings.
    """

    def __init__(self, config: PriorConfig):
        self.config = config
        self.env = roomnav.load(config.dataset, config.split, pixels=False, width=8, height=8,
                                horizon=config.steps, cache_size=2)

    def explore(self, house_ids: list[str]) -> list[tuple[str, np.ndarray, np.ndarray]]:
        """``(house id, positives, trials)`` of each house (:func:`explore_house`), in order."""
        return [(hid, *explore_house(self.env, hid, self.config)) for hid in house_ids]

    def close(self) -> None:
        self.env.close()


_EXPLORER: HouseExplorer | None = None


def _init_worker(config: PriorConfig) -> None:
    global _EXPLORER
    _EXPLORER = HouseExplorer(config)


def _explore_job(house_id: str) -> tuple[str, np.ndarray, np.ndarray]:
    return _EXPLORER.explore([house_id])[0]


class Trainer(trainer_lib.Trainer):
    """Explores the houses of a split one by one, pooling their counts; resumable after any house.

    The checkpoint (``<out>/state.json``) holds the pooled counts of the
    houses explored so far; houses are explored in the split's order, so a
    resumed run adds the same counts as an uninterrupted one.

    Args:
      config: the run's settings.
      out: the run's folder.
      workers: worker processes exploring houses in parallel (local backend).
      progress: show a progress bar.
      backend: where houses are explored, "local" or "ray".
      num_workers: Ray actors (default: one per cluster CPU, at most one per house).
      ray_address: the Ray cluster's address (default: a local instance).
    """

    unit = "house"

    def __init__(self, config: PriorConfig, out: str | os.PathLike, workers: int = 1, progress: bool = True,
                 backend: str = "local", num_workers: int | None = None, ray_address: str | None = None):
        if isinstance(workers, bool) or not isinstance(workers, int) or workers < 1:
            raise ValueError(f"workers {workers!r}: expected a positive integer")
        self.house_ids = [p.stem for p in dataset_lib.list_houses(config.dataset, config.split)][: config.houses]
        backend_options.check_backend(backend, num_workers, ray_address, len(self.house_ids), "houses")
        self.backend, self.num_workers, self.ray_address = backend, num_workers, ray_address
        super().__init__(config, out, len(self.house_ids), state_name="state.json", progress=progress,
                         desc="prior: houses")
        self.workers = workers
        self.pos = np.zeros((N, N), dtype=np.int64)
        self.trials = np.zeros((N, N), dtype=np.int64)
        self.resumed = self.iteration if self.resume() else 0

    def state(self) -> dict:
        return {"pos": self.pos.tolist(), "trials": self.trials.tolist()}

    def load_state(self, extra: dict) -> None:
        self.pos = np.asarray(extra["pos"], dtype=np.int64)
        self.trials = np.asarray(extra["trials"], dtype=np.int64)

    @contextlib.contextmanager
    def session(self):
        """Workers or Ray actors exploring the remaining houses in order (results come back in that order)."""
        jobs = self.house_ids[self.iteration:]
        with contextlib.ExitStack() as stack:
            if self.backend == "ray":
                from leaps_mj.learning import ray_prior

                self._ray = stack.enter_context(ray_prior.RayExplorers(
                    HouseExplorer, self.config, len(jobs), self.num_workers, self.ray_address))
                self._results = self._ray.explore(jobs)
            elif self.workers > 1 and len(jobs) > 1:
                pool = multiprocessing.get_context("spawn").Pool(min(self.workers, len(jobs)), _init_worker,
                                                                 (self.config,))
                stack.callback(pool.join)
                stack.callback(pool.terminate)
                self._results = pool.imap(_explore_job, jobs)
            else:
                explorer = HouseExplorer(self.config)
                stack.callback(explorer.close)
                self._results = (explorer.explore([hid])[0] for hid in jobs)
            yield

    def iterate(self) -> dict:
        t0 = time.perf_counter()
        hid, pos, trials = next(self._results)
        if hid != self.house_ids[self.iteration]:
            raise RuntimeError(f"explored house {hid!r} out of order (expected {self.house_ids[self.iteration]!r})")
        self.pos += pos
        self.trials += trials
        return {"pair_trials": int(trials.sum()), "positives": int(pos.sum()), "seconds": time.perf_counter() - t0}

    def result(self) -> dict:
        """The pooled counts and the prior learned from them."""
        return {"pos": self.pos, "trials": self.trials, "houses": len(self.house_ids), "resumed": self.resumed,
                "prior": semantic.learn_prior(self.pos, self.trials, floor=self.config.floor)}


def learn(config: PriorConfig, out: pathlib.Path, workers: int = 1, progress: bool = True, **backend) -> dict:
    """Explores the houses (resuming from the last checkpoint) and returns the pooled counts and prior.

    ``backend``: ``backend``, ``num_workers``, ``ray_address`` of :class:`Trainer`.

    Returns:
      ``{"pos": (9, 9), "trials": (9, 9), "prior": (9, 9), "houses": n, "resumed": n}``.

    Raises:
      ValueError: for a bad worker count, or a checkpoint in ``out`` made with other settings.
    """
    trainer = Trainer(config, out, workers, progress, **backend)
    trainer.train()
    return trainer.result()


def _neighbour_lines(prior: np.ndarray, nodes=("dining_room", "bedroom", "outdoor")) -> list[str]:
    """Most and least likely neighbours of some rooms, as text (the content of Fig. 2)."""
    lines = []
    for name in nodes:
        i = rooms.room_index(name)
        order = sorted((j for j in range(N) if j != i), key=lambda j: -prior[i, j])
        ranked = ", ".join(f"{rooms.GRAPH_NODES[j]} {prior[i, j]:.2f}" for j in order)
        lines.append(f"  {name}: {ranked}")
    return lines


def main(argv=None) -> int:
    p = argparse.ArgumentParser(prog="python -m leaps_mj.train prior", description=__doc__,
                                formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--preset", choices=sorted(PRESETS), default="cpu",
                   help="tiny: 3 houses x 2 trials; cpu: all houses x 10 trials; paper: x 50 trials")
    p.add_argument("--out", type=pathlib.Path, default=None, help="output folder (default runs/prior_<preset>)")
    p.add_argument("--dataset", default=None, help=f"dataset name or folder (default {dataset_lib.CANONICAL})")
    p.add_argument("--houses", type=int, default=None, help="explore only the first N houses")
    p.add_argument("--trials", type=int, default=None, help="runs per present room type per house")
    p.add_argument("--seed", type=int, default=None)
    p.add_argument("--workers", type=int, default=1, help="worker processes (local backend)")
    backend_options.add_backend_arguments(p, "houses' explorations", "each exploring one house at a time (default: one per "
                                   "cluster CPU, at most one per house)")
    args = p.parse_args(argv)
    overrides = {k: v for k, v in (("dataset", args.dataset), ("houses", args.houses),
                                   ("trials", args.trials), ("seed", args.seed)) if v is not None}
    try:
        config = dataclasses.replace(PRESETS[args.preset], **overrides)
    except ValueError as e:
        p.error(str(e))
    out = args.out or pathlib.Path("runs") / f"prior_{args.preset}"
    out.mkdir(parents=True, exist_ok=True)
    print(f"prior: {config}", flush=True)
    result = learn(config, out, workers=args.workers, backend=args.backend, num_workers=args.num_workers,
                   ray_address=args.ray_address)
    model = semantic.SemanticModel(result["prior"])
    model.to_json(out / "prior.json")
    semantic.plot_prior(result["prior"], out / "prior.png")
    rho = semantic.rank_correlation(result["prior"], rooms.reference_prior())
    runs = int(result["trials"].sum())
    print(f"explored {result['houses']} houses ({result['resumed']} resumed from {out / 'state.json'}), "
          f"{runs} pair trials")
    print("most to least likely neighbours:")
    print("\n".join(_neighbour_lines(result["prior"])))
    print(f"rank correlation (Spearman, 36 pairs) with the SUNCG reference prior: {rho:.3f}")
    print(f"wrote {out / 'prior.json'} and {out / 'prior.png'}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
