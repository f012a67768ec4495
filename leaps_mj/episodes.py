"""Fixed evaluation episodes: (house, start pose, target) stratified by plan length.

The paper evaluates on a fixed set of episodes in the test houses with at
least 500 episodes for each optimal plan length (fewest room-to-room hops from
the start room to a room of the target type). Episodes here are drawn the
same way, deterministically from a seed: for each plan length 1–5 the quota
is spread over the houses (and targets) that offer that length; each start is
a uniformly drawn free cell of a room at that distance, outside every target
room, with a uniform heading. Lengths no house offers are reported, not
invented.

Files: ``houses/<dataset>/episodes/<split>.jsonl``, one
:class:`leaps_mj.env.EpisodeSpec` per line.
"""

from __future__ import annotations

import collections
import json
import math
import pathlib

import mujoco
import numpy as np
import tqdm

from leaps_mj import dataset as dataset_lib
from leaps_mj import houses, rooms
from leaps_mj.env import EpisodeSpec, HouseModel, load_episodes

MAX_PLAN_LENGTH = 5


def episodes_path(dataset: str, split: str) -> pathlib.Path:
    """Where the fixed episodes of a split live."""
    dataset_lib.house_seed(0, split, 0)  # validates the split name
    return dataset_lib.dataset_dir(dataset) / "episodes" / f"{split}.jsonl"


def load_split(dataset: str, split: str) -> list[EpisodeSpec]:
    """The fixed episodes of a split.

    Raises:
      ValueError: if the file is missing (naming the command that makes it) or malformed.
    """
    path = episodes_path(dataset, split)
    if not path.exists():
        raise ValueError(f"no fixed episodes at {str(path)!r}; run `python tools/make_episodes.py --split {split}`")
    return load_episodes(path)


def house_models(dataset: str, split: str) -> list[HouseModel]:
    """Precomputed models (grids, room graphs) of every house of a split."""
    out = []
    for path in dataset_lib.list_houses(dataset, split):
        house = houses.House.load(path)
        xml = path.with_suffix(".xml").read_text()
        out.append(HouseModel(house, xml, mujoco.MjModel.from_xml_string(xml)))
    return out


def _start_cells(hm: HouseModel, target: str) -> dict[int, np.ndarray]:
    """Free cells outside target rooms, grouped by the plan length of their room."""
    dist = hm.distance_map(target)
    ok = hm.grid.free & ~hm.grid.room_mask(target) & (dist < 1e3)
    by_len = collections.defaultdict(list)
    for r in hm.house.rooms:
        if r.type == target:
            continue
        length = hm.plan_length(r.id, target)
        if length is None or length > MAX_PLAN_LENGTH:
            continue
        cells = np.flatnonzero((ok & (hm.grid.room_id == r.id)).ravel())
        if cells.size:
            by_len[length].append(cells)
    return {k: np.concatenate(v) for k, v in by_len.items()}


def generate(dataset: str, split: str, per_length: int, seed: int = 0) -> tuple[list[EpisodeSpec], dict]:
    """Draws the stratified episode set of a split.

    Args:
      dataset: dataset name or folder.
      split: "valid" or "test" (any split works).
      per_length: episodes wanted per plan length 1..5.
      seed: seed of the draws.

    Returns:
      (episodes sorted by house, target, plan length; counts per plan length).
    """
    if per_length < 1:
        raise ValueError(f"per_length {per_length!r}: expected a positive integer")
    rng = np.random.default_rng(seed)
    models = house_models(dataset, split)
    # (house index, target, length) → candidate cells.
    options = collections.defaultdict(list)
    for h, hm in enumerate(tqdm.tqdm(models, desc=f"{split}: start cells", leave=False)):
        for target in rooms.ROOM_TYPES:
            if target not in hm.house.room_types:
                continue
            for length, cells in _start_cells(hm, target).items():
                options[length].append((h, target, cells))
    episodes, counts = [], {}
    for length in range(1, MAX_PLAN_LENGTH + 1):
        opts = options.get(length, [])
        counts[length] = 0
        if not opts:
            continue
        # Spread the quota evenly over (house, target) options, round-robin.
        quota = [per_length // len(opts) + (i < per_length % len(opts)) for i in range(len(opts))]
        for (h, target, cells), n in zip(opts, quota):
            hm = models[h]
            dist = hm.distance_map(target)
            for cell in rng.choice(cells, size=n, replace=True):
                ij = np.unravel_index(cell, hm.grid.shape)
                xy = hm.grid.to_world(ij)
                yaw = float(rng.uniform(-math.pi, math.pi))
                episodes.append(EpisodeSpec(
                    house=hm.house.id, start=(round(float(xy[0]), 3), round(float(xy[1]), 3), round(yaw, 4)),
                    target=target, geodesic=round(float(dist[ij]), 3), plan_length=length,
                ))
                counts[length] += 1
    return episodes, counts


def write(path: str | pathlib.Path, episodes: list[EpisodeSpec]) -> None:
    """Writes episodes as JSON lines, atomically."""
    text = "".join(json.dumps(e.to_json(), sort_keys=True) + "\n" for e in episodes)
    dataset_lib.write_atomic(path, text.encode())
