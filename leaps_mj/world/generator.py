"""Semantic house generator: typed room programme → floor plan → doors → furniture.

A house is generated in four deterministic stages from one integer seed:

1. **Programme.** Which room types the house has and how many, drawn with the
   per-house frequencies of real homes (the original LEAPS release's SUNCG
   training houses: every house has a kitchen, 94 % a bathroom, 63 % a living
   room, …), plus the untyped rooms (closets, a mudroom beside the garage).
2. **Floor plan** (:mod:`leaps_mj.world.floorplan`). Double-loaded corridors,
   the commonest plan of real single-storey homes: a hallway with a row of
   rooms on each side, turned into an L with a second hallway and a bedroom
   wing in larger homes; the public chain kitchen – dining room – living room
   in one row, bedrooms alternating with bathrooms, the garage at one end
   behind a mudroom.
3. **Doors.** A room opens to a hallway it sits on with a probability by
   kind (``_HALL_DOOR_P``); neighbouring rooms share a door with a probability
   by kind or type pair (``_DOOR_P``: kitchen–dining high, mudroom–garage
   high, bedroom–garage never); a repair step connects any room left
   unreachable to its likeliest neighbour, so suites stay reached through a
   neighbour. A yard of outdoor space surrounds the house, reached by a front
   door, an optional back door and, in some houses, the garage's side door
   (a garage may also be reached from the yard only).
4. **Furniture** (:mod:`leaps_mj.world.furnish`). Items from the catalogue ``assets/furniture.json`` (boxes,
   cylinders, ellipsoids), placed against walls or free-standing, never in a
   door's clearance zone; every room stays reachable for a cylinder agent of
   radius :data:`leaps_mj.world.rooms.AGENT_RADIUS` (checked on the navigation grid,
   with capped retries).

The result is a :class:`House`: plain data (rooms, doors, walls, items) that
serialises to the JSON written beside each MJCF file and is all the
environment needs besides the compiled model.
"""


from __future__ import annotations

import numpy as np

from leaps_mj.world import floorplan, furnish, navgrid, rooms
from leaps_mj.world.houses import Door, House, Room, Wall

#: Door probability between two rooms that share a wall, by kind pair or, for
#: kinds not listed, by type pair (untyped kinds are ``indoor``; the
#: hallways' doors are in ``_HALL_DOOR_P``). Unlisted pairs get
#: ``_DEFAULT_DOOR_P``. Keys are normalised to sorted order below.
_DOOR_P = {
    ("kitchen", "dining_room"): 0.9,
    ("dining_room", "living_room"): 0.8,
    ("living_room", "office"): 0.7,
    ("kitchen", "living_room"): 0.5,
    ("bathroom", "bedroom"): 0.45,
    ("kitchen", "office"): 0.3,
    ("dining_room", "office"): 0.35,
    ("garage", "mudroom"): 0.9,
    ("kitchen", "mudroom"): 0.8,
    ("garage", "indoor"): 0.6,
    ("garage", "kitchen"): 0.35,
    ("indoor", "kitchen"): 0.3,
    ("indoor", "living_room"): 0.5,
    ("bathroom", "living_room"): 0.1,
    ("living_room", "garage"): 0.0,
    ("bedroom", "garage"): 0.0,
    ("bathroom", "garage"): 0.0,
}
_DOOR_P = {tuple(sorted(k)): v for k, v in _DOOR_P.items()}
_DEFAULT_DOOR_P = 0.05
#: Door probability between a hallway and a room on it, by the room's kind.
#: Below 1, the room may be reached through a neighbour instead (a kitchen
#: through the dining room, an en-suite bathroom through its bedroom, the
#: garage through the mudroom); the connectivity repair adds the hallway door
#: when it is not.
_HALL_DOOR_P = {
    "kitchen": 0.4,
    "dining_room": 0.75,
    "living_room": 0.9,
    "office": 0.4,
    "bathroom": 0.4,
    "bedroom": 1.0,
    "garage": 0.3,
    "hallway": 1.0,
    "foyer": 1.0,
    "mudroom": 0.35,
    "closet": 1.0,
}
#: Probability that a garage has no door into the house (reached from the
#: yard alone), and that a garage entered from inside also has a side door to
#: the yard (real garages often open only through the big garage door).
_GARAGE_YARD_ONLY_P = 0.3
_GARAGE_SIDE_DOOR_P = 0.25

#: Clearance radius (metres) every room must be reachable with: the agent's
#: radius plus a margin for turning.
_PASSAGE_RADIUS = rooms.AGENT_RADIUS + 0.15
_MAX_TRIES = 40
#: Layout attempts per sampled programme before a new programme is drawn.
_LAYOUT_TRIES = 10
#: Shortest wall that takes a door (door plus 0.25 m each side).
_MIN_DOOR_WALL = rooms.DOOR_WIDTH + 0.5


def door_probability(kind_a: str, kind_b: str) -> float:
    """Probability that two rooms sharing a wall get a door, by kind pair.

    Hallways use ``_HALL_DOOR_P`` (by the other room's kind); other pairs are
    looked up by kind, then by type, then get ``_DEFAULT_DOOR_P``.
    """
    if "hallway" in (kind_a, kind_b):
        return _HALL_DOOR_P[kind_b if kind_a == "hallway" else kind_a]
    key = tuple(sorted((kind_a, kind_b)))
    if key in _DOOR_P:
        return _DOOR_P[key]
    key = tuple(sorted((floorplan.room_type(kind_a), floorplan.room_type(kind_b))))
    return _DOOR_P.get(key, _DEFAULT_DOOR_P)


# --------------------------------------------------------------------------
# Stage 1: programme.


def sample_programme(rng: np.random.Generator) -> dict[str, int]:
    """Number of rooms of each type, with real homes' per-house frequencies.

    The presence of every target type keeps the frequencies of the reference's
    houses (what the statistics compare); counts and untyped rooms
    (``closet``, ``mudroom``) only make houses larger.
    """
    prog = {t: 0 for t in rooms.ROOM_TYPES}
    prog["kitchen"] = 1
    prog["outdoor"] = int(rng.random() < 0.9)
    prog["garage"] = int(prog["outdoor"] and rng.random() < 0.32)
    prog["living_room"] = int(rng.random() < 0.64)
    prog["dining_room"] = int(rng.random() < 0.38)
    prog["office"] = int(rng.random() < 0.36)
    prog["bedroom"] = 0 if rng.random() < 0.2 else int(rng.choice([1, 2, 3, 4], p=[0.3, 0.35, 0.25, 0.1]))
    # One bathroom per bedroom or two (en-suites and a main bathroom), at least one.
    n_bath = 1 if prog["bedroom"] <= 1 else int(rng.integers(prog["bedroom"] // 2, prog["bedroom"] // 2 + 2))
    prog["bathroom"] = 0 if rng.random() < 0.06 else n_bath
    prog["closet"] = int(rng.choice([0, 1, 2], p=[0.5, 0.35, 0.15]))
    # A mudroom / laundry between kitchen and garage in most houses with a garage.
    prog["mudroom"] = int(prog["garage"] and rng.random() < 0.7)
    return prog


def _shared_edge(a, b, min_len):
    """The wall segment two rects share, as (axis, fixed, lo, hi), or None."""
    ax0, ay0, ax1, ay1 = a
    bx0, by0, bx1, by1 = b
    for fixed_a, fixed_b, axis in ((ax1, bx0, "y"), (ax0, bx1, "y"), (ay1, by0, "x"), (ay0, by1, "x")):
        if abs(fixed_a - fixed_b) > 1e-6:
            continue
        if axis == "y":
            lo, hi = max(ay0, by0), min(ay1, by1)
        else:
            lo, hi = max(ax0, bx0), min(ax1, bx1)
        if hi - lo >= min_len:
            return axis, fixed_a, lo, hi
    return None


def _exterior_edges(rect, footprint_rects):
    """Edges of ``rect`` on the house's outer boundary: (axis, fixed, lo, hi, side)."""
    x0, y0, x1, y1 = rect
    edges = []
    for axis, fixed, lo, hi, side in (
        ("x", y0, x0, x1, -1), ("x", y1, x0, x1, +1), ("y", x0, y0, y1, -1), ("y", x1, y0, y1, +1)
    ):
        # Sample points along the edge just outside; exterior if outside all rooms.
        ts = np.linspace(lo + 0.1, hi - 0.1, 9)
        pts = [(fixed + side * 0.05, t) if axis == "y" else (t, fixed + side * 0.05) for t in ts]
        if all(not _inside(p, r) for p in pts for r in footprint_rects):
            edges.append((axis, fixed, lo, hi, side))
    return edges


def _inside(p, rect, pad=0.0):
    return rect[0] - pad <= p[0] <= rect[2] + pad and rect[1] - pad <= p[1] <= rect[3] + pad


def _door_on(axis, fixed, lo, hi, rng, width=rooms.DOOR_WIDTH, margin=0.25):
    """A door position on a wall segment, away from its ends; None if too short."""
    span = hi - lo - width - 2 * margin
    if span < 0:
        return None
    c = lo + margin + width / 2 + float(rng.uniform(0, span))
    c = round(c, 2)
    return (fixed, c) if axis == "y" else (c, fixed)


def _doors(rng, plan_rooms, hallways, outdoor_id):
    """Interior doors; guarantees every room is reachable from the main hallway.

    Args:
      rng: the house's generator.
      plan_rooms: (kind, rect) per room, the yard (kind ``outdoor``) last if any.
      hallways: ids of the hallways, the main one first.
      outdoor_id: id of the yard, or -1.

    Returns:
      (doors, garage_inside): whether the garage (if any) has a door into the
      house; a garage without one is reached through the yard.
    """
    doors: list[Door] = []
    linked = set()
    kinds = [k for k, _ in plan_rooms]
    yard_only = "garage" in kinds and outdoor_id >= 0 and rng.random() < _GARAGE_YARD_ONLY_P
    closed = {i for i, k in enumerate(kinds) if k == "outdoor" or (yard_only and k == "garage")}

    def add(a, b, center, axis, width=rooms.DOOR_WIDTH):
        doors.append(Door((a, b), center, width, axis))
        linked.add(tuple(sorted((a, b))))

    n = len(plan_rooms)
    for a in range(n):
        for b in range(a + 1, n):
            if a in closed or b in closed:
                continue
            edge = _shared_edge(plan_rooms[a][1], plan_rooms[b][1], _MIN_DOOR_WALL)
            if edge is None:
                continue
            if rng.random() < door_probability(kinds[a], kinds[b]):
                c = _door_on(*edge, rng)
                if c is not None:
                    add(a, b, c, edge[0])
    # Repair connectivity: join each unreachable room to its best neighbour.
    for _ in range(n):
        reach = _reachable(n, linked, hallways[0], skip=outdoor_id)
        missing = [i for i in range(n) if i not in reach and i not in closed]
        if not missing:
            break
        best = None
        for i in missing:
            for j in reach:
                edge = _shared_edge(plan_rooms[i][1], plan_rooms[j][1], _MIN_DOOR_WALL)
                if edge is None:
                    continue
                # A hallway competes with its own door probability, so a room
                # meant to be reached through a neighbour (a suite) stays so.
                p = door_probability(kinds[i], kinds[j])
                if p > 0 and (best is None or p > best[0]):
                    best = (p, i, j, edge)
        if best is None:
            raise _Retry("a room has no wall long enough for a door to the rest")
        _, i, j, edge = best
        add(i, j, _door_on(*edge, rng), edge[0])
    else:
        raise _Retry("could not connect every room")
    return doors, "garage" in kinds and not yard_only


def _reachable(n, linked, start, skip=None):
    adj = {i: set() for i in range(n)}
    for a, b in linked:
        adj[a].add(b)
        adj[b].add(a)
    seen, stack = {start}, [start]
    while stack:
        for j in adj[stack.pop()]:
            if j not in seen and j != skip:
                seen.add(j)
                stack.append(j)
    return seen


class _Retry(Exception):
    """A sampled layout cannot be completed; the generator draws another."""


def _exterior_doors(rng, plan_rooms, house_rects, outdoor_id, hallways, foyer, garage_inside):
    """Front door, optional back door and the garage's doors to the yard.

    The garage always has its (closed) garage door; its side door is drawn
    with ``_GARAGE_SIDE_DOOR_P`` when it has a door into the house and is
    always there when it has not.

    Returns:
      (doors, garage_door_panels) where a panel is (axis, fixed, lo, hi).
    """
    doors, panels = [], []
    ext = {i: _exterior_edges(r, house_rects) for i, (t, r) in enumerate(plan_rooms) if t != "outdoor"}

    def place(i, width=rooms.DOOR_WIDTH, avoid=None):
        edges = [e for e in ext[i] if e[3] - e[2] >= width + 0.5]
        rng.shuffle(edges)
        for axis, fixed, lo, hi, _ in edges:
            if avoid is not None and avoid[0] == axis and avoid[1] == fixed:
                # Keep clear of the garage-door panel on the same wall.
                segs = [(lo, avoid[2]), (avoid[3], hi)]
            else:
                segs = [(lo, hi)]
            for slo, shi in segs:
                c = _door_on(axis, fixed, slo, shi, rng, width)
                if c is not None:
                    doors.append(Door((i, outdoor_id), c, width, axis))
                    return True
        return False

    types = [t for t, _ in plan_rooms]
    # Front door: the main hallway's end if it reaches the outside, else the
    # foyer, the other hallway, a public room.
    order = [hallways[0]] + ([foyer] if foyer is not None else []) + list(hallways[1:])
    order += [i for i, t in enumerate(types) if t == "living_room"]
    order += [i for i, t in enumerate(types) if t in ("dining_room", "kitchen")]
    order += list(range(1, len(types)))
    if rng.random() < 0.12 and "living_room" in types:
        order.insert(0, types.index("living_room"))
    for i in order:
        if i != outdoor_id and types[i] != "garage" and place(i):
            break
    else:
        raise _Retry("no room can take a front door")
    if "kitchen" in types and rng.random() < 0.15:
        place(types.index("kitchen"))
    if "garage" in types:
        g = types.index("garage")
        edges = sorted(ext[g], key=lambda e: -(e[3] - e[2]))
        axis, fixed, lo, hi, _ = edges[0]
        mid = (lo + hi) / 2
        panel = (axis, fixed, round(mid - 1.3, 2), round(mid + 1.3, 2))
        panels.append(panel)
        side_door = not garage_inside or rng.random() < _GARAGE_SIDE_DOOR_P
        if side_door and not place(g, avoid=panel):
            raise _Retry("garage has no wall for a side door")
    return doors, panels


# --------------------------------------------------------------------------
# Walls.


def _merge(intervals):
    out = []
    for lo, hi in sorted(intervals):
        if out and lo <= out[-1][1] + 1e-6:
            out[-1][1] = max(out[-1][1], hi)
        else:
            out.append([lo, hi])
    return out


def _subtract(intervals, gaps):
    out = []
    for lo, hi in intervals:
        cur = [(lo, hi)]
        for glo, ghi in gaps:
            nxt = []
            for a, b in cur:
                if ghi <= a or glo >= b:
                    nxt.append((a, b))
                    continue
                if glo > a:
                    nxt.append((a, glo))
                if ghi < b:
                    nxt.append((ghi, b))
            cur = nxt
        out += [(a, b) for a, b in cur if b - a > 1e-3]
    return out


def _walls(room_rects, doors, panels, lot, has_yard):
    """Wall boxes with door gaps, garage-door panels and the lot fence."""
    t = rooms.WALL_THICKNESS
    lines: dict[tuple[str, float], list] = {}
    for x0, y0, x1, y1 in room_rects:
        for axis, fixed, lo, hi in (("x", y0, x0, x1), ("x", y1, x0, x1), ("y", x0, y0, y1), ("y", x1, y0, y1)):
            lines.setdefault((axis, round(fixed, 3)), []).append((lo, hi))
    gaps: dict[tuple[str, float], list] = {}
    for d in doors:
        fixed = d.center[1] if d.axis == "x" else d.center[0]
        along = d.center[0] if d.axis == "x" else d.center[1]
        gaps.setdefault((d.axis, round(fixed, 3)), []).append((along - d.width / 2 - t / 2, along + d.width / 2 + t / 2))
    for axis, fixed, lo, hi in panels:
        gaps.setdefault((axis, round(fixed, 3)), []).append((lo, hi))
    walls = []

    def box(axis, fixed, lo, hi, cls, height):
        if axis == "x":
            rect = (lo - t / 2, fixed - t / 2, hi + t / 2, fixed + t / 2)
        else:
            rect = (fixed - t / 2, lo - t / 2, fixed + t / 2, hi + t / 2)
        walls.append(Wall(cls, tuple(round(v, 3) for v in rect), height))

    for (axis, fixed), ivs in sorted(lines.items()):
        for lo, hi in _subtract(_merge(ivs), gaps.get((axis, fixed), [])):
            box(axis, fixed, lo + t / 2, hi - t / 2, "wall", rooms.WALL_HEIGHT)
    for axis, fixed, lo, hi in panels:
        box(axis, fixed, lo + t / 2, hi - t / 2, "garage_door", 2.3)
    if has_yard:
        x0, y0, x1, y1 = lot
        for axis, fixed, lo, hi in (("x", y0, x0, x1), ("x", y1, x0, x1), ("y", x0, y0, y1), ("y", x1, y0, y1)):
            box(axis, fixed, lo, hi, "fence", 1.6)
    return walls


# --------------------------------------------------------------------------
# Assembly.


def generate(seed: int, house_id: str = "house") -> House:
    """Generates one house, deterministically from ``seed``.

    Layouts that cannot be completed (a room with no wall for a door, a room
    left unreachable by furniture) are redrawn from the same generator, at
    most ``_MAX_TRIES`` times.

    Raises:
      RuntimeError: if no valid house was found within the retry cap.
    """
    rng = np.random.default_rng(seed)
    last = None
    for attempt in range(_MAX_TRIES):
        # Layouts are redrawn for the same programme first, so that hard
        # programmes (many rooms, a dining room) are not under-represented.
        if attempt % _LAYOUT_TRIES == 0:
            prog = sample_programme(rng)
        try:
            house = _generate_once(rng, seed, house_id, prog)
            # Every room reachable with room to spare: passages through
            # furnished rooms (the kitchen behind the living room) at least
            # 2 x _PASSAGE_RADIUS wide, so the 9-action controller does not
            # get stuck threading them.
            navgrid.NavGrid(house, radius=_PASSAGE_RADIUS).check_reachable()
            return house
        except (_Retry, furnish.NoRoom, navgrid.Unreachable) as e:
            last = e
    raise RuntimeError(f"house {house_id!r} (seed {seed}): no valid layout in {_MAX_TRIES} tries; last: {last}")


def _generate_once(rng, seed, house_id, prog) -> House:
    plan = floorplan.floor_plan(rng, prog)
    layout = list(plan.rooms)
    house_rects = [r for _, r in layout]
    hx0 = min(r[0] for r in house_rects)
    hy0 = min(r[1] for r in house_rects)
    hx1 = max(r[2] for r in house_rects)
    hy1 = max(r[3] for r in house_rects)
    has_yard = bool(prog["outdoor"])
    if has_yard:
        m = [round(float(rng.uniform(2.5, 4.0)), 2) for _ in range(4)]
        lot = (hx0 - m[0], hy0 - m[1], hx1 + m[2], hy1 + m[3])
        layout = layout + [("outdoor", lot)]
    else:
        lot = (hx0, hy0, hx1, hy1)
    outdoor_id = len(layout) - 1 if has_yard else -1
    doors, garage_inside = _doors(rng, layout, plan.hallways, outdoor_id)
    panels = []
    if has_yard:
        ext_doors, panels = _exterior_doors(rng, layout, house_rects, outdoor_id, plan.hallways, plan.foyer,
                                            garage_inside)
        doors += ext_doors
    counts: dict[str, int] = {}
    house_rooms = []
    for i, (kind, r) in enumerate(layout):
        counts[kind] = counts.get(kind, 0) + 1
        house_rooms.append(Room(i, floorplan.room_type(kind), f"{kind}_{counts[kind]}", r))
    walls = _walls(house_rects, doors, panels, lot, has_yard)
    items = furnish.furnish(rng, house_rooms, doors, walls, lot)
    return House(
        id=house_id, seed=int(seed), rooms=tuple(house_rooms), doors=tuple(doors),
        walls=tuple(walls), items=tuple(items), lot=tuple(round(v, 3) for v in lot),
    )
