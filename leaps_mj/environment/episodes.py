"""Fixed evaluation episodes: (house, start pose, target) stratified by plan length.

The paper evaluates on a fixed set of episodes in the test houses with at
least 500 episodes for each optimal plan length (fewest room-to-room hops from
the start room to a room of the target type). Episodes here are drawn the
same way, deterministically from a seed: for each plan length 1–5 the quota
is spread over the houses (and targets) that offer that length; each start is
a uniformly drawn free cell of a room at that distance, outside every target
room, with a uniform heading. Lengths no house offers are reported, not
invented.

A second set, the *hop* episodes (:func:`generate_hops`), measures the
sub-policies LEAPS hands control to: for every graph node (the 8 room types
and the untyped ``indoor`` node) starts one and two doors from its nearest
room, the reach a sub-policy is given between two replans.

Files: ``houses/<dataset>/episodes/<split>.jsonl`` and
``houses/<dataset>/episodes/hops_<split>.jsonl``, one
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
from leaps_mj.world import files
from leaps_mj.world import houses, rooms

MAX_PLAN_LENGTH = 5
#: Door distances of the hop episodes: plan lengths from the start room to the node's nearest room.
HOP_DISTANCES = (1, 2)
#: Fixed episode sets: name -> (file name pattern, options of tools/make_episodes.py that write it).
EPISODE_SETS = {"plan_length": ("{split}.jsonl", ""), "hops": ("hops_{split}.jsonl", "--hops "),
                "hops_large": ("hops_large_{split}.jsonl", "--hops --large ")}
#: The hop sets: name -> (starts per node and door distance by split, seed of the draw). ``hops_large`` is an
#: independent draw (another seed), over three times the size: for differences of a few points, and for a
#: figure on starts that no training decision was ever made on.
HOP_SETS = {"hops": ({"valid": 20, "test": 30}, 0), "hops_large": ({"valid": 100, "test": 100}, 1)}
_MAX_DRAWS = 1000  # draws of one hop start before concluding that all its candidate cells lie in the node


def episodes_path(dataset: str, split: str, kind: str = "plan_length") -> pathlib.Path:
    """Where a fixed episode set of a split lives.

    Args:
      dataset: dataset name or folder.
      split: split name.
      kind: a key of :data:`EPISODE_SETS`.

    Raises:
      ValueError: for an unknown split or set name.
    """
    dataset_lib.house_seed(0, split, 0)  # validates the split name
    if kind not in EPISODE_SETS:
        raise ValueError(f"unknown episode set {kind!r}; expected one of {list(EPISODE_SETS)}")
    return dataset_lib.dataset_dir(dataset) / "episodes" / EPISODE_SETS[kind][0].format(split=split)


def load_split(dataset: str, split: str, kind: str = "plan_length") -> list[EpisodeSpec]:
    """A fixed episode set of a split (see :func:`episodes_path`).

    Raises:
      ValueError: if the file is missing (naming the command that makes it) or malformed.
    """
    path = episodes_path(dataset, split, kind)
    if not path.exists():
        raise ValueError(f"no fixed episodes at {str(path)!r}; run "
                         f"`python tools/make_episodes.py {EPISODE_SETS[kind][1]}--dataset {dataset} --split {split}`")
    return load_episodes(path)


def house_models(dataset: str, split: str) -> list[HouseModel]:
    """Precomputed models (grids, room graphs) of every house of a split."""
    out = []
    for path in dataset_lib.list_houses(dataset, split):
        house = houses.House.load(path)
        xml = path.with_suffix(".xml").read_text()
        out.append(HouseModel(house, xml, mujoco.MjModel.from_xml_string(xml)))
    return out


def _room_cells(hm: HouseModel, target: str) -> dict[int, list[np.ndarray]]:
    """Free cells (flat indices) of each room outside the target rooms, grouped by the room's plan length."""
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
    return dict(by_len)


def _start_cells(hm: HouseModel, target: str) -> dict[int, np.ndarray]:
    """Free cells outside target rooms, grouped by the plan length of their room."""
    return {k: np.concatenate(v) for k, v in _room_cells(hm, target).items()}


def _spec(hm: HouseModel, target: str, cell: int, yaw: float, length: int) -> EpisodeSpec:
    """The episode starting at a grid cell (flat index) with a heading, rounded as written to file."""
    ij = np.unravel_index(cell, hm.grid.shape)
    xy = hm.grid.to_world(ij)
    return EpisodeSpec(
        house=hm.house.id, start=(round(float(xy[0]), 3), round(float(xy[1]), 3), round(yaw, 4)),
        target=target, geodesic=round(float(hm.distance_map(target)[ij]), 3), plan_length=length,
    )


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
            for cell in rng.choice(cells, size=n, replace=True):
                episodes.append(_spec(models[h], target, cell, float(rng.uniform(-math.pi, math.pi)), length))
                counts[length] += 1
    return episodes, counts


def starts_in_node(hm: HouseModel, spec: EpisodeSpec) -> bool:
    """Whether an episode's start already lies in its target node, by the env's own semantic bits.

    A doorway cell labelled as one room also carries the bits of the room
    beyond the door, and a yard cell at the front door is untyped indoor space.
    """
    return hm.in_node(hm.semantic_bits(*spec.start[:2]), rooms.room_index(spec.target))


def generate_hops(dataset: str, split: str, per_node: int, seed: int = 0,
                  distances=HOP_DISTANCES) -> tuple[list[EpisodeSpec], dict]:
    """Draws the hop episodes of a split: starts a fixed number of doors from each graph node.

    For every node of :data:`leaps_mj.world.rooms.GRAPH_NODES` and door
    distance d, ``per_node`` starts are spread evenly over the houses that have
    a room at plan length d from the node (houses lacking the node are
    skipped; the remainder goes to a seeded random choice of houses). Each
    start is in a uniformly drawn one of those rooms (so that the yard, the
    largest room, does not crowd out the others), at a uniform free cell of
    it, redrawn while the env's bits already place it in the node, with a
    uniform heading. Every (node, d) pair
    draws from its own stream ``SeedSequence([seed, node index, d])``, so
    changing one quota leaves the other episodes as they were.

    Args:
      dataset: dataset name or folder.
      split: split name.
      per_node: starts per node and distance.
      seed: seed of the draws.
      distances: door distances (plan lengths, 1..MAX_PLAN_LENGTH).

    Returns:
      (episodes sorted by house, target and distance (consecutive episodes share a compiled house);
      ``{node: {d: {"episodes": n, "houses": n}}}``).

    Raises:
      ValueError: naming a bad ``per_node`` or distance.
    """
    if isinstance(per_node, bool) or not isinstance(per_node, int) or per_node < 1:
        raise ValueError(f"per_node {per_node!r}: expected a positive integer")
    distances = tuple(distances)
    bad = [d for d in distances if isinstance(d, bool) or not isinstance(d, int) or not 1 <= d <= MAX_PLAN_LENGTH]
    if bad or not distances or len(set(distances)) != len(distances):
        raise ValueError(f"distances {distances!r}: expected distinct integers in 1..{MAX_PLAN_LENGTH}")
    models = house_models(dataset, split)
    episodes, counts = [], {}
    for k, node in enumerate(tqdm.tqdm(rooms.GRAPH_NODES, desc=f"{split}: hop starts", leave=False)):
        cells_by_house = [(hm, _room_cells(hm, node)) for hm in models if node in hm.house.room_types]
        counts[node] = {}
        for d in distances:
            opts = [(hm, cells[d]) for hm, cells in cells_by_house if d in cells]
            counts[node][d] = {"episodes": 0, "houses": len(opts)}
            if not opts:
                continue
            rng = np.random.default_rng(np.random.SeedSequence([seed, k, d]))
            extra = set(rng.permutation(len(opts))[:per_node % len(opts)].tolist())
            for i, (hm, room_cells) in enumerate(opts):
                for _ in range(per_node // len(opts) + (i in extra)):
                    for _ in range(_MAX_DRAWS):
                        cells = room_cells[rng.integers(len(room_cells))]
                        spec = _spec(hm, node, rng.choice(cells), float(rng.uniform(-math.pi, math.pi)), d)
                        if not starts_in_node(hm, spec):
                            break
                    else:
                        raise RuntimeError(f"{hm.house.id}: no start {d} doors from {node!r} outside it")
                    episodes.append(spec)
                    counts[node][d]["episodes"] += 1
    episodes.sort(key=lambda e: (e.house, rooms.room_index(e.target), e.plan_length))
    return episodes, counts


def write(path: str | pathlib.Path, episodes: list[EpisodeSpec]) -> None:
    """Writes episodes as JSON lines, atomically."""
    text = "".join(json.dumps(e.to_json(), sort_keys=True) + "\n" for e in episodes)
    files.write_atomic(path, text.encode())


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


def select_episodes(specs, per_length: int | None = None, limit: int | None = None, seed: int = 0,
                    stratum=None) -> list[int]:
    """Indices of a subset of fixed episodes, still stratified by plan length (or another key).

    Args:
      specs: the split's episodes.
      per_length: draw this many episodes (without replacement, seeded) of
        each plan length (each stratum); None keeps all.
      limit: then keep only the first this many indices.
      seed: seed of the draw.
      stratum: the key an episode is stratified by (default its plan length;
        the hop benchmark uses (target, plan length)).

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
        key = stratum or (lambda spec: spec.plan_length)
        for value in sorted({key(s) for s in specs}, key=lambda v: (v is None, v)):
            pool = [i for i in indices if key(specs[i]) == value]
            chosen += rng.choice(pool, size=min(per_length, len(pool)), replace=False).tolist()
        indices = sorted(chosen)
    return indices[:limit]
