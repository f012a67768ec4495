"""Hop success split by the start: what a turn on the spot shows, the start room's type, its doors, or where its door on the way lies.

``python tools/hop_visibility.py --dataset roomnav-v2 --split test [--large] [--by view|room|doors|way] FOLDER ...``

With ``--by view`` (the default), for every one-door hop episode (``--distance`` to change) it turns
the camera through a full circle at the start position (12 headings, 30° apart, nothing else moves)
and notes whether any see-object of the target's type (the pixels the see test counts) comes into
view. A learner that perceives the target but cannot act on it fails the episodes where it does; one
that does not explore fails those where it does not; targets without see-objects (``outdoor``,
``indoor``) form a third group. ``--by room`` groups the episodes by the type of the room the agent
starts in (``indoor``: a hallway or other untyped space), ``--by doors`` by how many doors that room
has: where a learner must choose among many doors it cannot see through, it falls behind a teacher
that knows the way. ``--by way`` groups them by the nearest door of the start room that leads on to
the target: whether it lies ahead of the start heading (within 45°), to the side or behind (beyond
135°), and whether within 3 m; a door beside the agent is out of the first frame. Then, for each hop result folder given (written by ``python -m
leaps_mj.evaluation.hops``, on the same dataset, split and hop set), it prints each agent's success
within ``--horizon`` steps per group, with 95 % Wilson intervals.
"""

from __future__ import annotations

import argparse
import collections
import json
import math
import pathlib
import sys

import numpy as np

from leaps_mj.environment import episodes as episodes_lib
from leaps_mj.environment import roomnav
from leaps_mj.evaluation import harness, stats
from leaps_mj.world import rooms

#: Headings of the look around, evenly spaced from the start heading.
HEADINGS = 12
#: Groups of episodes by what a turn shows, in the printed order.
GROUPS = ("target comes into view", "target never in view", "no see-objects")
#: The ways of grouping the episodes.
SPLITS = ("view", "room", "doors", "way")
#: Start rooms with at least this many doors form one group.
MANY_DOORS = 5
#: Metres within which the door on the way counts as near (``--by way``).
NEAR_DOOR = 3.0
#: Degrees from the start heading beyond which the door on the way lies to the side, and behind.
SIDE, BEHIND = 45.0, 135.0
#: Where the door on the way can lie from the start heading (``--by way``).
BEARINGS = ("ahead", "side", "behind")


def in_view_on_turning(env, spec) -> bool:
    """Whether a see-object of ``spec.target``'s type shows in a full turn at the start position."""
    env.reset_to(spec)
    physics, mask = env.physics, env.segment_luts[1][rooms.room_index(spec.target)]
    x, y, yaw = spec.start
    for k in range(HEADINGS):
        physics.set_agent_pose(np.array([x, y, yaw + 2 * math.pi * k / HEADINGS]))
        physics.forward_kinematics()
        segments, _ = env.renderer.render_segments(physics.data.ptr)
        if mask.take(segments).any():
            return True
    return False


def groups(dataset: str, split: str, distance: int, by: str = "view", kind: str = "hops") -> dict[int, str]:
    """Episode index (in the split's hop file ``kind``) -> its group, for the hops ``distance`` doors away.

    Raises:
      ValueError: for an unknown ``by``.
    """
    if by not in SPLITS:
        raise ValueError(f"unknown grouping {by!r}; expected one of {list(SPLITS)}")
    specs = [(i, s) for i, s in enumerate(episodes_lib.load_split(dataset, split, kind)) if s.plan_length == distance]
    if by != "view":
        models = {hm.house.id: hm for hm in episodes_lib.house_models(dataset, split)}
        return {i: _start_room(models[s.house], s, by) for i, s in specs}
    env = roomnav.load(dataset, split, width=40, height=30)
    try:
        return {i: (GROUPS[2] if not rooms.SEE_OBJECTS.get(s.target)
                    else GROUPS[0] if in_view_on_turning(env, s) else GROUPS[1]) for i, s in specs}
    finally:
        env.close()


def _start_room(hm, spec, by: str) -> str:
    """The group of an episode's start by its room: the room's type (``room``), how many doors it has
    (``doors``), or where its nearest door on the way to the target lies (``way``).

    Raises:
      ValueError: for a start in no room of the house.
    """
    room = {r.id: r for r in hm.house.rooms}.get(hm.room_at(spec.start[:2]))
    if room is None:
        raise ValueError(f"start {tuple(spec.start)} lies in no room of house {hm.house.id}")
    if by == "room":
        return room.type
    doors = [door for door in hm.house.doors if room.id in door.rooms]
    if by == "doors":
        return _doors_group(len(doors))
    return _way_group(spec, [door for door in doors if hm.plan_length(
        next((r for r in door.rooms if r != room.id), room.id), spec.target) == spec.plan_length - 1])


def _way_group(spec, way) -> str:
    """The ``--by way`` group of a start: the bearing and distance of the nearest of the doors ``way``."""
    x, y, yaw = spec.start
    distance, door = min(((math.hypot(d.center[0] - x, d.center[1] - y), d) for d in way), key=lambda t: t[0])
    bearing = abs(math.degrees(math.remainder(math.atan2(door.center[1] - y, door.center[0] - x) - yaw, 2 * math.pi)))
    where = BEARINGS[0] if bearing <= SIDE else BEARINGS[1] if bearing < BEHIND else BEARINGS[2]
    return _way_name(where, distance <= NEAR_DOOR)


def _way_name(where: str, near: bool) -> str:
    """The name of the ``--by way`` group of doors lying ``where`` from the start heading, near or not."""
    return f"{where}, {'≤' if near else '>'} {NEAR_DOOR:g} m"


#: Groups of ``--by way``, in the printed order.
WAY_GROUPS = tuple(_way_name(where, near) for near in (True, False) for where in BEARINGS)


def _doors_group(doors: int) -> str:
    """The name of the group of start rooms with ``doors`` doors."""
    return f"{MANY_DOORS}+ doors" if doors >= MANY_DOORS else f"{doors} door" + "s" * (doors != 1)


def _order(by: str, sizes: collections.Counter) -> list[str]:
    """The printed order of the groups: as listed (``view``, ``way``), by door count (``doors``), largest first (``room``)."""
    if by == "view":
        return list(GROUPS)
    if by == "way":
        return [g for g in WAY_GROUPS if g in sizes]
    if by == "doors":
        return [g for g in map(_doors_group, range(MANY_DOORS + 1)) if g in sizes]
    return sorted(sizes, key=lambda g: (-sizes[g], g))


def check_folder(folder: pathlib.Path, dataset: str, split: str, kind: str) -> list[pathlib.Path]:
    """The folder's per-agent CSVs, after checking that it ran this split's hop episodes ``kind``."""
    config_path = folder / "config.json"
    if not config_path.is_file():
        raise ValueError(f"{str(folder)!r} holds no config.json: expected a folder written by "
                         "python -m leaps_mj.evaluation.hops")
    config = json.loads(config_path.read_text())
    ran = (pathlib.Path(str(config.get("dataset"))).name, config.get("split"), config.get("episodes"))
    if ran != (pathlib.Path(dataset).name, split, kind):
        raise ValueError(f"{str(folder)!r} ran {ran}; expected the episodes {kind!r} of {dataset} / {split}")
    return sorted(folder.glob("episodes_*.csv"))


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("folders", nargs="+", help="hop result folders (python -m leaps_mj.evaluation.hops --out)")
    parser.add_argument("--dataset", default="roomnav-v2")
    parser.add_argument("--split", default="test")
    parser.add_argument("--distance", type=int, default=1, help="doors from the target (1 or 2)")
    parser.add_argument("--horizon", type=int, default=60, help="success within this many steps")
    parser.add_argument("--by", choices=SPLITS, default="view",
                        help="group by what a turn at the start shows, the start room's type, its doors, or where its "
                             "door on the way to the target lies")
    parser.add_argument("--large", action="store_true", help="the large hop set (python -m leaps_mj.evaluation.hops --large)")
    args = parser.parse_args(argv)
    if args.distance not in episodes_lib.HOP_DISTANCES or args.horizon < 1:
        parser.error(f"--distance {args.distance}, --horizon {args.horizon}: expected a distance in "
                     f"{list(episodes_lib.HOP_DISTANCES)} and a positive horizon")
    kind = "hops_large" if args.large else "hops"
    try:
        csvs = [(folder, path) for folder in map(pathlib.Path, args.folders)
                for path in check_folder(folder, args.dataset, args.split, kind)]
        group_of = groups(args.dataset, args.split, args.distance, args.by, kind)
    except ValueError as e:
        print(f"error: {e}", file=sys.stderr)
        return 2
    sizes = collections.Counter(group_of.values())
    order = _order(args.by, sizes)
    print(f"{len(group_of)} hop episodes {args.distance} door(s) away ({args.dataset} / {args.split}); "
          f"success within {args.horizon} steps\n")
    print("| run | agent | " + " | ".join(f"{g} (n = {sizes[g]})" for g in order) + " |")
    print("|---|---|" + "---|" * len(order))
    for folder, path in csvs:
        rows = [r for r in harness.read_rows(path) if int(r["episode"]) in group_of]
        ok = stats.success_at(rows, args.horizon)
        of = np.array([group_of[int(r["episode"])] for r in rows])
        cells = []
        for g in order:
            k, n = int(ok[of == g].sum()), int((of == g).sum())
            low, high = stats.wilson(k, n)
            cells.append(f"{100 * k / n:.1f}% [{100 * low:.1f}, {100 * high:.1f}]" if n else "–")
        agent = path.stem.removeprefix("episodes_")
        print(f"| {folder} | {agent} | " + " | ".join(cells) + " |")
    return 0


if __name__ == "__main__":
    sys.exit(main())
