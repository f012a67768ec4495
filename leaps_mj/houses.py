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
4. **Furniture.** Items from the catalogue ``assets/furniture.json`` (boxes,
   cylinders, ellipsoids), placed against walls or free-standing, never in a
   door's clearance zone; every room stays reachable for a cylinder agent of
   radius :data:`leaps_mj.rooms.AGENT_RADIUS` (checked on the navigation grid,
   with capped retries).

The result is a :class:`House`: plain data (rooms, doors, walls, items) that
serialises to the JSON written beside each MJCF file and is all the
environment needs besides the compiled model.
"""

from __future__ import annotations

import dataclasses
import functools
import json
import pathlib

import numpy as np

from leaps_mj import rooms

ASSETS_DIR = pathlib.Path(__file__).resolve().parent.parent / "assets"
FORMAT_VERSION = 1

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
#: Lowest height of hanging items (wall cabinets) in the catalogue.
_HANGING_Z = 1.45
#: Layout attempts per sampled programme before a new programme is drawn.
_LAYOUT_TRIES = 10
#: Shortest wall that takes a door (door plus 0.25 m each side).
_MIN_DOOR_WALL = rooms.DOOR_WIDTH + 0.5


def door_probability(type_a: str, type_b: str) -> float:
    """Probability that two rooms sharing a wall get a door, by type pair."""
    key = tuple(sorted((type_a, type_b)))
    return _DOOR_P.get(key, _DEFAULT_DOOR_P)


@dataclasses.dataclass(frozen=True)
class Room:
    """An axis-aligned rectangular room; ``rect`` is (x0, y0, x1, y1) in metres.

    Outdoor space is one room whose rect is the whole lot; a point belongs to
    it when it is in the lot and in no indoor room.
    """

    id: int
    type: str
    name: str
    rect: tuple[float, float, float, float]

    @property
    def area(self) -> float:
        x0, y0, x1, y1 = self.rect
        return (x1 - x0) * (y1 - y0)


@dataclasses.dataclass(frozen=True)
class Door:
    """An opening of ``width`` metres centred at ``center`` in a wall.

    ``axis`` is the direction the wall runs: ``"x"`` for a wall of constant y.
    """

    rooms: tuple[int, int]
    center: tuple[float, float]
    width: float
    axis: str


@dataclasses.dataclass(frozen=True)
class Geom:
    """One labelled primitive of the scene (MuJoCo geom conventions)."""

    name: str
    cls: str
    shape: str
    pos: tuple[float, float, float]
    size: tuple[float, ...]
    rgba: tuple[float, float, float, float]


@dataclasses.dataclass(frozen=True)
class Item:
    """A furniture item: its catalogue key, class, room and primitives.

    ``footprint`` is the (x0, y0, x1, y1) floor area it blocks, or None for
    items the agent can pass over or under (rugs, wall cabinets).
    """

    id: int
    key: str
    cls: str
    room: int
    room_type: str
    footprint: tuple[float, float, float, float] | None
    geoms: tuple[Geom, ...]


@dataclasses.dataclass(frozen=True)
class Wall:
    """A wall (or fence, or garage door) box: ``rect`` is its floor footprint."""

    cls: str
    rect: tuple[float, float, float, float]
    height: float


@dataclasses.dataclass(frozen=True)
class House:
    """A generated house: everything but the compiled MuJoCo model."""

    id: str
    seed: int
    rooms: tuple[Room, ...]
    doors: tuple[Door, ...]
    walls: tuple[Wall, ...]
    items: tuple[Item, ...]
    lot: tuple[float, float, float, float]

    @property
    def room_types(self) -> tuple[str, ...]:
        return tuple(r.type for r in self.rooms)

    @property
    def indoor_rooms(self) -> tuple[Room, ...]:
        return tuple(r for r in self.rooms if r.type != "outdoor")

    def connectivity(self) -> list[tuple[int, int]]:
        """Sorted list of room-id pairs joined by at least one door."""
        return sorted({tuple(sorted(d.rooms)) for d in self.doors})

    def type_adjacency(self) -> set[tuple[str, str]]:
        """Type pairs (sorted) joined by a door; untyped space is ``indoor``."""
        return {
            tuple(sorted((self.rooms[a].type, self.rooms[b].type)))
            for a, b in self.connectivity()
            if self.rooms[a].type != self.rooms[b].type
        }

    def obstacles(self) -> list[tuple[float, float, float, float]]:
        """Floor rectangles the agent cannot enter: walls and furniture."""
        rects = [w.rect for w in self.walls]
        rects += [it.footprint for it in self.items if it.footprint is not None]
        return rects

    def to_json(self) -> dict:
        """The metadata written beside the MJCF (plain JSON types only)."""
        return {
            "format_version": FORMAT_VERSION,
            "id": self.id,
            "seed": self.seed,
            "lot": list(self.lot),
            "rooms": [dataclasses.asdict(r) for r in self.rooms],
            "doors": [dataclasses.asdict(d) for d in self.doors],
            "connectivity": [list(p) for p in self.connectivity()],
            "walls": [dataclasses.asdict(w) for w in self.walls],
            "items": [
                {**{k: v for k, v in dataclasses.asdict(it).items() if k != "geoms"},
                 "geoms": [dataclasses.asdict(g) for g in it.geoms]}
                for it in self.items
            ],
            "navigation": {"agent_radius": rooms.AGENT_RADIUS, "cell": 0.1},
        }

    @classmethod
    def from_json(cls, data: dict, source: str = "<dict>") -> "House":
        """Rebuilds a House from :meth:`to_json` output.

        Raises:
          ValueError: if the data is not a house of this format, naming ``source``.
        """
        try:
            if data.get("format_version") != FORMAT_VERSION:
                raise ValueError(
                    f"format_version {data.get('format_version')!r}, expected {FORMAT_VERSION}"
                )
            house_rooms = tuple(
                Room(r["id"], r["type"], r["name"], tuple(r["rect"])) for r in data["rooms"]
            )
            for r in house_rooms:
                if r.type not in rooms.GRAPH_NODES:
                    raise ValueError(f"unknown room type {r.type!r}")
            return cls(
                id=data["id"],
                seed=int(data["seed"]),
                rooms=house_rooms,
                doors=tuple(
                    Door(tuple(d["rooms"]), tuple(d["center"]), d["width"], d["axis"])
                    for d in data["doors"]
                ),
                walls=tuple(Wall(w["cls"], tuple(w["rect"]), w["height"]) for w in data["walls"]),
                items=tuple(
                    Item(
                        it["id"], it["key"], it["cls"], it["room"], it["room_type"],
                        tuple(it["footprint"]) if it["footprint"] is not None else None,
                        tuple(
                            Geom(g["name"], g["cls"], g["shape"], tuple(g["pos"]),
                                 tuple(g["size"]), tuple(g["rgba"]))
                            for g in it["geoms"]
                        ),
                    )
                    for it in data["items"]
                ),
                lot=tuple(data["lot"]),
            )
        except (KeyError, TypeError, AttributeError, ValueError) as e:
            raise ValueError(f"{source}: not a valid leaps_mj house description ({e})") from None

    @classmethod
    def load(cls, path: str | pathlib.Path) -> "House":
        """Reads a house JSON file.

        Raises:
          ValueError: if the file is missing, not JSON, or not a house.
        """
        path = pathlib.Path(path)
        try:
            text = path.read_text()
        except OSError as e:
            raise ValueError(f"cannot read house file {str(path)!r}: {e.strerror}") from None
        try:
            data = json.loads(text)
        except json.JSONDecodeError as e:
            raise ValueError(f"house file {str(path)!r} is not valid JSON: {e}") from None
        if not isinstance(data, dict):
            raise ValueError(f"house file {str(path)!r} holds {type(data).__name__}, expected an object")
        return cls.from_json(data, source=str(path))


@functools.lru_cache(maxsize=1)
def catalogue() -> dict:
    """The furniture catalogue ``assets/furniture.json``."""
    with open(ASSETS_DIR / "furniture.json") as f:
        return json.load(f)


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
# Stage 4: furniture.


def _door_zones(doors):
    zones = []
    for d in doors:
        cx, cy = d.center
        half = d.width / 2 + 0.25
        if d.axis == "x":
            zones.append((cx - half, cy - 1.1, cx + half, cy + 1.1))
        else:
            zones.append((cx - 1.1, cy - half, cx + 1.1, cy + half))
    return zones


def _overlap(a, b, pad=0.0):
    return a[0] < b[2] + pad and b[0] < a[2] + pad and a[1] < b[3] + pad and b[1] < a[3] + pad


def _place_item(rng, key, spec, room_rect, blocked, zones, inner_pad, tall=(), hanging=(), sides=None):
    """Samples a pose for one item; returns (footprint, frame) or None.

    ``frame`` is (origin xy, along unit vector, inward unit vector, w, d, h).
    """
    x0, y0, x1, y1 = room_rect
    ix0, iy0, ix1, iy1 = x0 + inner_pad, y0 + inner_pad, x1 - inner_pad, y1 - inner_pad
    for _ in range(30):
        w, d = float(rng.uniform(*spec["w"])), float(rng.uniform(*spec["d"]))
        h = float(rng.uniform(*spec["h"]))
        place = spec["place"]
        if place == "center":
            if rng.random() < 0.5:
                along, inward = np.array([1.0, 0.0]), np.array([0.0, 1.0])
                fw, fd = w, d
            else:
                along, inward = np.array([0.0, 1.0]), np.array([-1.0, 0.0])
                fw, fd = d, w
            m = 0.65  # room to walk round: the agent is 0.4 m across
            if ix1 - ix0 - 2 * m < fw or iy1 - iy0 - 2 * m < fd:
                continue
            fx = float(rng.uniform(ix0 + m, ix1 - m - fw))
            fy = float(rng.uniform(iy0 + m, iy1 - m - fd))
            fp = (fx, fy, fx + fw, fy + fd)
            origin = np.array([fp[0], fp[1]]) if inward[1] > 0 else np.array([fp[2], fp[1]])
        else:
            # Walls south, east, north, west: (corner, along, inward, length).
            side = int(rng.integers(4)) if sides is None else sides[int(rng.integers(len(sides)))]
            corner, along, inward, length = (
                ((ix0, iy0), (1.0, 0.0), (0.0, 1.0), ix1 - ix0),
                ((ix1, iy0), (0.0, 1.0), (-1.0, 0.0), iy1 - iy0),
                ((ix1, iy1), (-1.0, 0.0), (0.0, -1.0), ix1 - ix0),
                ((ix0, iy1), (0.0, -1.0), (1.0, 0.0), iy1 - iy0),
            )[side]
            along, inward = np.array(along), np.array(inward)
            if length < w + 0.1:
                continue
            origin = np.array(corner) + along * float(rng.uniform(0.05, length - w - 0.05))
            far = origin + along * w + inward * d
            fp = (min(origin[0], far[0]), min(origin[1], far[1]), max(origin[0], far[0]), max(origin[1], far[1]))
        if any(_overlap(fp, z) for z in zones):
            continue
        if place != "hanging" and not spec.get("walkable") and any(_overlap(fp, b, 0.05) for b in blocked):
            continue
        # A wall cabinet never cuts into a fridge or a pantry.
        if place == "hanging" and any(_overlap(fp, b) for b in tall):
            continue
        if place != "hanging" and spec.get("z", 0.0) + h > _HANGING_Z and any(_overlap(fp, b) for b in hanging):
            continue
        return fp, (origin, along, inward, w, d, h)
    return None


def _item_geoms(item_id, key, spec, frame, room_id, room_type):
    origin, along, inward, w, d, h = frame
    z_base = spec.get("z", 0.0)
    geoms = []
    for k, part in enumerate(spec["parts"]):
        bx0, by0, bz0, bx1, by1, bz1 = part["box"]
        cls = part.get("class", spec["class"])
        c_local = np.array([(bx0 + bx1) / 2 * w, (by0 + by1) / 2 * d])
        xy = origin + along * c_local[0] + inward * c_local[1]
        hx, hy, hz = (bx1 - bx0) / 2 * w, (by1 - by0) / 2 * d, (bz1 - bz0) / 2 * h
        if abs(along[0]) < 0.5:  # along runs in y: swap half extents
            hx, hy = hy, hx
        z = z_base + (bz0 + bz1) / 2 * h
        shape = part["shape"]
        if shape == "box":
            size = (hx, hy, hz)
        elif shape == "cylinder":
            size = (min(hx, hy), hz)
        else:
            shape, size = "ellipsoid", (hx, hy, hz)
        geoms.append(Geom(
            name=f"{cls}__{room_type}__r{room_id}__i{item_id}__p{k}",
            cls=cls, shape=shape,
            pos=tuple(round(float(v), 3) for v in (xy[0], xy[1], z)),
            size=tuple(round(float(v), 3) for v in size),
            rgba=tuple(part["rgba"]),
        ))
    return tuple(geoms)


def _furnish(rng, house_rooms, doors, walls, lot):
    cat = catalogue()
    zones = _door_zones(doors)
    blocked = [w.rect for w in walls]
    tall = []  # footprints of items reaching the height of wall cabinets
    hanging = []  # floor rectangles under wall cabinets
    items = []
    indoor_rects = [r.rect for r in house_rooms if r.type != "outdoor"]
    for room in house_rooms:
        plan = cat["rooms"][room.type]
        keys = list(plan["required"])
        opt = list(plan["optional"])
        rng.shuffle(opt)
        # Big rooms (a full-depth living room) get at least two optional items.
        min_opt = min(2, len(opt)) if room.type != "outdoor" and room.area > 30.0 else 0
        keys += opt[: int(rng.integers(min_opt, len(opt) + 1))]
        if room.type == "bathroom":
            # A bathroom has a bathtub or a shower, rarely both.
            keys = [k for k in keys if k not in ("bathtub", "shower")] + [str(rng.choice(["bathtub", "shower"]))]
        wall_side = {}  # catalogue key -> wall it stands against (0 S, 1 E, 2 N, 3 W)
        for key in keys:
            spec = cat["items"][key]
            if room.type == "outdoor":
                fp_frame = _place_tree(rng, spec, lot, indoor_rects, blocked, zones)
            else:
                args = (rng, key, spec, room.rect, blocked, zones, rooms.WALL_THICKNESS / 2 + 0.06, tall, hanging)
                fp_frame = None
                if spec.get("faces") in wall_side:
                    # On the wall facing its partner (a television facing the sofa).
                    fp_frame = _place_item(*args, sides=[(wall_side[spec["faces"]] + 2) % 4])
                if fp_frame is None:
                    fp_frame = _place_item(*args)
            if fp_frame is None:
                if key in plan["required"]:
                    raise _Retry(f"no room for required {key} in {room.name}")
                continue
            fp, frame = fp_frame
            if spec["place"] == "wall":
                inward = tuple(int(round(v)) for v in frame[2])
                wall_side[key] = {(0, 1): 0, (-1, 0): 1, (0, -1): 2, (1, 0): 3}[inward]
            item_id = len(items)
            no_footprint = spec["place"] == "hanging" or spec.get("walkable", False)
            footprint = None if no_footprint else tuple(round(float(v), 3) for v in fp)
            if spec["place"] == "hanging":
                hanging.append(fp)
            if footprint is not None:
                blocked.append(footprint)
                if spec.get("z", 0.0) + frame[5] > _HANGING_Z:
                    tall.append(footprint)
            items.append(Item(
                id=item_id, key=key, cls=spec["class"], room=room.id, room_type=room.type,
                footprint=footprint,
                geoms=_item_geoms(item_id, key, spec, frame, room.id, room.type),
            ))
    return items


def _place_tree(rng, spec, lot, house_rects, blocked, zones):
    x0, y0, x1, y1 = lot
    for _ in range(30):
        w = float(rng.uniform(*spec["w"]))
        h = float(rng.uniform(*spec["h"]))
        fx = float(rng.uniform(x0 + 0.3, x1 - 0.3 - w))
        fy = float(rng.uniform(y0 + 0.3, y1 - 0.3 - w))
        fp = (fx, fy, fx + w, fy + w)
        if any(_overlap(fp, r, 1.2) for r in house_rects) or any(_overlap(fp, z) for z in zones):
            continue
        if any(_overlap(fp, b, 0.1) for b in blocked):
            continue
        frame = (np.array([fx, fy]), np.array([1.0, 0]), np.array([0, 1.0]), w, w, h)
        # The trunk alone blocks the floor: the crown is above the agent.
        trunk = (fx + 0.4 * w, fy + 0.4 * w, fx + 0.6 * w, fy + 0.6 * w)
        return trunk, frame
    return None


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
    from leaps_mj import navgrid  # local: navgrid imports this module

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
        except (_Retry, navgrid.Unreachable) as e:
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
    items = _furnish(rng, house_rooms, doors, walls, lot)
    return House(
        id=house_id, seed=int(seed), rooms=tuple(house_rooms), doors=tuple(doors),
        walls=tuple(walls), items=tuple(items), lot=tuple(round(v, 3) for v in lot),
    )
