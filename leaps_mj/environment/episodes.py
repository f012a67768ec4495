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
:class:`leaps_mj.environment.roomnav.EpisodeSpec` per line.
"""

from __future__ import annotations

import collections
import json
import math
import pathlib

import mujoco
import numpy as np
import tqdm

from leaps_mj.environment.roomnav import EpisodeSpec, HouseModel, load_episodes
from leaps_mj.world import dataset as dataset_lib
from leaps_mj.world import houses, rooms

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


def run_episode(env, agent, spec, horizon: int, observer=None) -> dict:
    """Runs one fixed episode to success or the horizon.

    Args:
      env: a :class:`leaps_mj.environment.roomnav.RoomNavEnvironment` whose own horizon is at
        least ``horizon``.
      agent: an :class:`leaps_mj.planning.agents.Agent`.
      spec: the :class:`leaps_mj.environment.roomnav.EpisodeSpec`.
      horizon: maximum number of steps.
      observer: optional object with ``begin(env, spec, agent)``,
        ``step(timestep, action, info)`` (after each step, with the agent's
        info for the action taken) and ``end(result)``, e.g. the MCAP recorder.

    Returns:
      ``{"house", "target", "plan_length", "geodesic", "success",
      "success_step" (int or None), "steps", "final_distance",
      "subtarget_changes"}``.

    Raises:
      ValueError: if the horizon is not a positive integer or exceeds the environment's.
    """
    if isinstance(horizon, bool) or not isinstance(horizon, int) or horizon < 1:
        raise ValueError(f"horizon {horizon!r}: expected a positive integer")
    if horizon > env.config.horizon:
        raise ValueError(f"horizon {horizon} exceeds the environment's horizon {env.config.horizon}; "
                         "load the environment with a larger horizon")
    ts = env.reset_to(spec)
    agent.reset(spec.target)
    if observer is not None:
        observer.begin(env, spec, agent)
    steps, changes, last_subtarget = 0, 0, None
    while not ts.last() and steps < horizon:
        action = agent.step(ts)
        info = agent.info()
        if info["subtarget"] != last_subtarget:
            changes += last_subtarget is not None
            last_subtarget = info["subtarget"]
        ts = env.step(action)
        steps += 1
        if observer is not None:
            observer.step(ts, action, info)
    success = bool(env.task.success)
    result = {
        "house": spec.house, "target": spec.target, "plan_length": spec.plan_length,
        "geodesic": spec.geodesic, "success": success, "success_step": steps if success else None,
        "steps": steps, "final_distance": round(float(env.task.distance), 3), "subtarget_changes": changes,
    }
    if observer is not None:
        observer.end(result)
    return result


def episode_seed(seed: int, index: int) -> int:
    """The seed of the agent of episode ``index``: the same for every agent and worker layout."""
    return int(np.random.SeedSequence([seed, index]).generate_state(1)[0])


def select_episodes(specs, per_length: int | None = None, limit: int | None = None, seed: int = 0) -> list[int]:
    """Indices of a subset of fixed episodes, still stratified by plan length.

    Args:
      specs: the split's episodes.
      per_length: draw this many episodes (without replacement, seeded) of
        each plan length; None keeps all.
      limit: then keep only the first this many indices.
      seed: seed of the draw.

    Returns:
      Sorted episode indices.
    """
    for name, value in (("per_length", per_length), ("limit", limit)):
        if value is not None and (isinstance(value, bool) or not isinstance(value, int) or value < 1):
            raise ValueError(f"{name} {value!r}: expected a positive integer or None")
    indices = list(range(len(specs)))
    if per_length is not None:
        rng = np.random.default_rng(seed)
        chosen = []
        for length in sorted({s.plan_length for s in specs}, key=lambda v: (v is None, v)):
            pool = [i for i in indices if specs[i].plan_length == length]
            chosen += rng.choice(pool, size=min(per_length, len(pool)), replace=False).tolist()
        indices = sorted(chosen)
    return indices[:limit]
