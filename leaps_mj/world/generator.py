"""Semantic house generator: typed room programme → floor plan → doors → furniture.

A house is generated in four deterministic stages from one integer seed:

1. **Programme.** Which room types the house has and how many, drawn with the
   per-house frequencies of real homes (the original LEAPS release's SUNCG
   training houses: every house has a kitchen, 94 % a bathroom, 63 % a living
   room, …).
2. **Floor plan.** A "double-loaded corridor" plan, the commonest plan of real
   single-storey homes: a hallway (untyped indoor space) runs along the house
   with a row of rooms on each side; a living room may span the full depth at
   one end and a garage at the other. The public rooms are placed in the chain
   kitchen – dining room – living room, the office next to the living room and
   bedrooms alternate with bathrooms in the private wing, so the room graph has
   the regularities of real homes. Room sizes vary per type; half of the
   houses have a stepped outline; an entry foyer is added when both ends of
   the hallway are taken.
3. **Doors.** A room opens to the hallway it sits on with a probability by
   type (``_HALL_DOOR_P``); neighbouring rooms share a door with a probability
   by type pair (``_DOOR_P``: kitchen–dining high, bedroom–garage never); a
   repair step connects any room left unreachable. A yard of outdoor space
   surrounds the house, reached by a front door, an optional back door and
   the garage's side door (a garage may be reached from the yard only).
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

from leaps_mj.world import furnish, navgrid, rooms
from leaps_mj.world.houses import Door, House, Room, Wall

#: Door probability between two rooms that share a wall, by type pair (the
#: hallway's doors are in ``_HALL_DOOR_P``). Unlisted pairs get
#: ``_DEFAULT_DOOR_P``. Keys are normalised to sorted order below.
_DOOR_P = {
    ("kitchen", "dining_room"): 0.9,
    ("dining_room", "living_room"): 0.8,
    ("living_room", "office"): 0.7,
    ("kitchen", "living_room"): 0.5,
    ("bathroom", "bedroom"): 0.45,
    ("kitchen", "office"): 0.3,
    ("dining_room", "office"): 0.2,
    ("garage", "indoor"): 0.6,
    ("garage", "kitchen"): 0.35,
    ("indoor", "kitchen"): 0.3,
    ("indoor", "living_room"): 0.5,
    ("bathroom", "living_room"): 0.1,
    ("bedroom", "garage"): 0.0,
    ("bathroom", "garage"): 0.0,
}
_DOOR_P = {tuple(sorted(k)): v for k, v in _DOOR_P.items()}
_DEFAULT_DOOR_P = 0.05
#: Door probability between the hallway and a room on it, by the room's type.
#: Below 1, the room may be reached through a neighbour instead (a kitchen
#: through the dining room, an en-suite bathroom through its bedroom); the
#: connectivity repair adds the hallway door when it is not.
_HALL_DOOR_P = {
    "kitchen": 0.4,
    "dining_room": 0.6,
    "living_room": 0.9,
    "office": 0.5,
    "bathroom": 0.55,
    "bedroom": 1.0,
    "garage": 0.55,
    "indoor": 1.0,
}

#: Width range (metres, along the row) per room type.
_WIDTH = {
    "kitchen": (3.0, 4.5),
    "dining_room": (3.3, 4.5),
    "living_room": (4.0, 6.0),
    "office": (2.6, 3.6),
    "bedroom": (3.0, 4.5),
    "bathroom": (2.2, 3.0),
    "indoor": (1.8, 2.6),
    "foyer": (1.8, 2.4),
    "garage": (3.8, 5.0),
}
_MAX_TRIES = 40
#: Layout attempts per sampled programme before a new programme is drawn.
_LAYOUT_TRIES = 10
#: Shortest wall that takes a door (door plus 0.25 m each side).
_MIN_DOOR_WALL = rooms.DOOR_WIDTH + 0.5


def door_probability(type_a: str, type_b: str) -> float:
    """Probability that two rooms sharing a wall get a door, by type pair."""
    key = tuple(sorted((type_a, type_b)))
    return _DOOR_P.get(key, _DEFAULT_DOOR_P)


# --------------------------------------------------------------------------
# Stage 1: programme.


def sample_programme(rng: np.random.Generator) -> dict[str, int]:
    """Number of rooms of each type, with real homes' per-house frequencies."""
    prog = {t: 0 for t in rooms.ROOM_TYPES}
    prog["kitchen"] = 1
    prog["outdoor"] = int(rng.random() < 0.9)
    prog["garage"] = int(prog["outdoor"] and rng.random() < 0.32)
    prog["living_room"] = int(rng.random() < 0.64)
    prog["dining_room"] = int(rng.random() < 0.38)
    prog["office"] = int(rng.random() < 0.36)
    prog["bedroom"] = 0 if rng.random() < 0.2 else int(rng.choice([1, 2, 3], p=[0.35, 0.4, 0.25]))
    prog["bathroom"] = 0 if rng.random() < 0.06 else (1 if prog["bedroom"] <= 1 else int(rng.choice([1, 2])))
    prog["indoor_extra"] = int(rng.random() < 0.35)  # closet / laundry / storage
    return prog


# --------------------------------------------------------------------------
# Stage 2: floor plan.


def _floor_plan(rng: np.random.Generator, prog: dict[str, int]) -> tuple[list[tuple[str, tuple]], dict]:
    """Lays rooms out as rectangles around a central hallway.

    Returns:
      (rooms as (type, rect) with the hallway first, layout facts).
    """
    full_west = "living_room" if prog["living_room"] and rng.random() < 0.5 else None
    public = [t for t in ("living_room", "dining_room", "kitchen") if prog[t] and t != full_west]
    if rng.random() < 0.5:
        public.reverse()
    bedrooms = ["bedroom"] * prog["bedroom"]
    baths = ["bathroom"] * prog["bathroom"]
    private = []
    while bedrooms or baths:
        if bedrooms:
            private.append(bedrooms.pop())
        if baths:
            private.append(baths.pop())
    if prog["indoor_extra"]:
        private.insert(int(rng.integers(0, len(private) + 1)), "indoor")
    def width(t):
        lo, hi = _WIDTH[t]
        return float(rng.uniform(lo, hi))

    # The office opens off the living room (commonest) or the kitchen, else
    # it heads the other row. ``public`` starts at the west end (the
    # full-depth living room, when there is one, is further west still).
    north = list(public)
    south = []
    if prog["office"]:
        u = rng.random()
        if full_west and u < 0.7:
            # Both rows start beside the full-depth living room.
            (north if rng.random() < 0.5 else south).insert(0, "office")
        elif "living_room" in north and u < 0.7:
            north.insert(0 if north[0] == "living_room" else len(north), "office")
        elif u < 0.85:
            north.insert(0 if north[0] == "kitchen" else len(north), "office")
        else:
            south.append("office")
    # A house whose hallway has no outside end (a full-depth living room at
    # one end, the garage at the other) gets an entry foyer in the public row.
    if full_west and prog["garage"]:
        north.insert(int(rng.integers(1, len(north) + 1)), "foyer")
    # Split the private wing to balance the row lengths.
    nw = [width(t) for t in north]
    sw = [width(t) for t in south]
    pw = [width(t) for t in private]
    for t, w in zip(private, pw):
        if sum(nw) <= sum(sw):
            north.append(t)
            nw.append(w)
        else:
            south.append(t)
            sw.append(w)
    if not north:
        north, nw = ["indoor"], [width("indoor")]
    if not south:
        south, sw = ["indoor"], [width("indoor")]
    row_len = max(sum(nw), sum(sw))
    # Stretch the shorter row; a large gap gets a storage room instead.
    for names, ws in ((north, nw), (south, sw)):
        gap = row_len - sum(ws)
        if gap > 0.5 * sum(ws) and gap >= _WIDTH["indoor"][0]:
            names.append("indoor")
            ws.append(gap)
        else:
            scale = row_len / sum(ws)
            ws[:] = [w * scale for w in ws]
    if rng.random() < 0.5:
        north, south, nw, sw = south, north, sw, nw

    depth_s = float(rng.uniform(3.2, 4.8))
    depth_n = float(rng.uniform(3.2, 4.8))
    # Wide enough for a door at its ends (door plus 0.25 m each side).
    hall = float(rng.uniform(1.5, 1.8))
    depth = depth_s + hall + depth_n
    x = 0.0
    out: list[tuple[str, tuple]] = []
    foyer = None
    if full_west:
        w = width(full_west) + 0.5
        west_room = (full_west, (0.0, 0.0, w, depth))
        x = w
    hall_rect = (x, depth_s, x + row_len, depth_s + hall)
    out.append(("indoor", hall_rect))
    if full_west:
        out.append(west_room)
    # Half of the houses have a stepped outline: some rooms are shallower
    # than their row, their outer wall set back (the yard fills the notch).
    stepped = rng.random() < 0.5
    for names, ws, y0, y1, outer in ((south, sw, 0.0, depth_s, 0), (north, nw, depth_s + hall, depth, 1)):
        cx = x
        for t, w in zip(names, ws):
            if t == "foyer":
                foyer = len(out)
                t = "indoor"
            rect = [cx, y0, cx + w, y1]
            max_cut = min(1.2, y1 - y0 - 3.0)
            if stepped and max_cut >= 0.4 and rng.random() < 0.4:
                cut = float(rng.uniform(0.4, max_cut))
                rect[1 + 2 * outer] += cut if outer == 0 else -cut
            out.append((t, tuple(rect)))
            cx += w
    x_end = x + row_len
    if prog["garage"]:
        out.append(("garage", (x_end, 0.0, x_end + width("garage"), depth)))
    # Mirror half of the houses so the garage / living room swap ends.
    if rng.random() < 0.5:
        total = max(r[2] for _, r in out)
        out = [(t, (total - r[2], r[1], total - r[0], r[3])) for t, r in out]
    out = [(t, tuple(round(v, 2) for v in r)) for t, r in out]
    return out, {"depth": depth, "foyer": foyer}


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


def _doors(rng, plan_rooms, hall_id, outdoor_id):
    """Interior and exterior doors; guarantees every room is reachable."""
    doors: list[Door] = []
    linked = set()

    def add(a, b, center, axis, width=rooms.DOOR_WIDTH):
        doors.append(Door((a, b), center, width, axis))
        linked.add(tuple(sorted((a, b))))

    n = len(plan_rooms)
    for a in range(n):
        for b in range(a + 1, n):
            ta, ra = plan_rooms[a][0], plan_rooms[a][1]
            tb, rb = plan_rooms[b][0], plan_rooms[b][1]
            if "outdoor" in (ta, tb):
                continue
            edge = _shared_edge(ra, rb, _MIN_DOOR_WALL)
            if edge is None:
                continue
            if hall_id in (a, b):
                p = _HALL_DOOR_P[tb if a == hall_id else ta]
            else:
                p = door_probability(ta, tb)
            if rng.random() < p:
                c = _door_on(*edge, rng)
                if c is not None:
                    add(a, b, c, edge[0])
    # Repair connectivity: join each unreachable room to its best neighbour.
    for _ in range(n):
        reach = _reachable(n, linked, hall_id, skip=outdoor_id)
        # A garage may be reached from the yard alone (its side door).
        missing = [i for i in range(n) if i not in reach and i != outdoor_id
                   and not (plan_rooms[i][0] == "garage" and outdoor_id >= 0)]
        if not missing:
            break
        best = None
        for i in missing:
            for j in reach:
                edge = _shared_edge(plan_rooms[i][1], plan_rooms[j][1], _MIN_DOOR_WALL)
                if edge is None:
                    continue
                # The hallway competes with its own door probability, so a room
                # meant to be reached through a neighbour (a suite) stays so.
                p = (_HALL_DOOR_P[plan_rooms[i][0]] if j == hall_id
                     else door_probability(plan_rooms[i][0], plan_rooms[j][0]))
                if p > 0 and (best is None or p > best[0]):
                    best = (p, i, j, edge)
        if best is None:
            raise _Retry("a room has no wall long enough for a door to the rest")
        _, i, j, edge = best
        add(i, j, _door_on(*edge, rng), edge[0])
    else:
        raise _Retry("could not connect every room")
    return doors


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


def _exterior_doors(rng, plan_rooms, house_rects, outdoor_id, foyer=None):
    """Front door, optional back door and the garage's doors to the yard.

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
    # Front door: the hallway end if it reaches the outside, else a public room.
    order = [0] + ([foyer] if foyer is not None else [])
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
        if not place(g, avoid=panel):
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
            navgrid.NavGrid(house).check_reachable()
            return house
        except (_Retry, furnish.NoRoom, navgrid.Unreachable) as e:
            last = e
    raise RuntimeError(f"house {house_id!r} (seed {seed}): no valid layout in {_MAX_TRIES} tries; last: {last}")


def _generate_once(rng, seed, house_id, prog) -> House:
    layout, facts = _floor_plan(rng, prog)
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
    doors = _doors(rng, layout, 0, outdoor_id)
    panels = []
    if has_yard:
        ext_doors, panels = _exterior_doors(rng, layout, house_rects, outdoor_id, facts["foyer"])
        doors += ext_doors
    counts: dict[str, int] = {}
    house_rooms = []
    for i, (t, r) in enumerate(layout):
        label = "hallway" if i == 0 else t
        counts[label] = counts.get(label, 0) + 1
        house_rooms.append(Room(i, t, f"{label}_{counts[label]}", r))
    walls = _walls(house_rects, doors, panels, lot, has_yard)
    items = furnish.furnish(rng, house_rooms, doors, walls, lot)
    return House(
        id=house_id, seed=int(seed), rooms=tuple(house_rooms), doors=tuple(doors),
        walls=tuple(walls), items=tuple(items), lot=tuple(round(v, 3) for v in lot),
    )
