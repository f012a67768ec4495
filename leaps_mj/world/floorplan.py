"""Floor plans: where each room of a programme goes (stage 2 of generation).

Two plans, both made of double-loaded corridors, the commonest plan of real
single-storey homes:

* **corridor**: one hallway runs along the house with a row of rooms on each
  side; a full-depth living room may close one end and the garage the other.
* **L**: the same main wing, turned at one end into a second wing: a second
  hallway runs at right angles to the first along the end of the main wing,
  with the bedroom wing on both sides of it (one column beside the main wing's
  end, one above the main wing's row). Rooms of the bedroom wing are reached
  through the second hallway, so plans from an en-suite bathroom to the
  kitchen take four or five room-to-room steps, as in large real homes.

The public rooms form the chain kitchen – dining room – living room in one
row, the office beside the living room or the kitchen, bedrooms alternate with
bathrooms; a garage spans the full depth at the end of the main wing, and when
the house has a mudroom (laundry) it sits between the kitchen and the garage,
so that the garage is entered through it. Rooms are *kinds*: the target room
types plus the untyped kinds of :data:`UNTYPED_KINDS` (all the graph node
``indoor``), which the door stage treats differently (a hallway opens to every
room on it, a mudroom to the garage).
"""

from __future__ import annotations

import dataclasses

import numpy as np

from leaps_mj.world import rooms

#: Untyped room kinds (the semantic graph's ``indoor`` node): hallways, the
#: entry foyer, the mudroom / laundry between kitchen and garage, closets.
UNTYPED_KINDS = ("hallway", "foyer", "mudroom", "closet")

#: Width range (metres, along the row) per room kind.
_WIDTH = {
    "kitchen": (3.0, 4.5),
    "dining_room": (3.3, 4.5),
    "living_room": (4.0, 6.0),
    "office": (2.6, 3.6),
    "bedroom": (3.0, 4.5),
    "bathroom": (2.2, 3.0),
    "closet": (1.8, 2.6),
    "foyer": (1.8, 2.4),
    "mudroom": (2.0, 2.8),
    "garage": (3.8, 5.0),
}
#: Shortest gap at the end of a row left open to the yard (shorter ones are
#: closed by stretching the row's rooms).
_MIN_OPEN = 1.8
#: Probability of the L plan when the private wing has at least
#: ``_L_MIN_PRIVATE`` rooms (smaller homes keep the single corridor).
_L_PLAN_P = 0.9
_L_MIN_PRIVATE = 3
#: Depth range of a row (metres, across the hallway) and hallway width (wide
#: enough for a door at its ends: the door plus 0.25 m each side).
_ROW_DEPTH = (3.2, 4.8)
_HALL_WIDTH = (1.5, 1.8)


def room_type(kind: str) -> str:
    """The room type (graph node) of a room kind: untyped kinds are ``indoor``."""
    return rooms.INDOOR if kind in UNTYPED_KINDS else kind


@dataclasses.dataclass(frozen=True)
class Plan:
    """A floor plan.

    Attributes:
      rooms: (kind, rect) per room, rect (x0, y0, x1, y1) in metres rounded to
        centimetres; the main hallway first.
      hallways: ids (indices into ``rooms``) of the hallways, the main one first.
      foyer: id of the entry foyer, or None.
      shape: ``"corridor"`` or ``"L"``.
    """

    rooms: tuple[tuple[str, tuple[float, float, float, float]], ...]
    hallways: tuple[int, ...]
    foyer: int | None
    shape: str


def _private_wing(rng: np.random.Generator, prog: dict[str, int]) -> list[str]:
    """Bedrooms alternating with bathrooms, closets inserted at random places."""
    bedrooms = ["bedroom"] * prog["bedroom"]
    baths = ["bathroom"] * prog["bathroom"]
    private = []
    while bedrooms or baths:
        if bedrooms:
            private.append(bedrooms.pop())
        if baths:
            private.append(baths.pop())
    for _ in range(prog["closet"]):
        private.insert(int(rng.integers(0, len(private) + 1)), "closet")
    return private


def _fit(row: list[list], length: float, at: int) -> None:
    """Makes a row ``length`` long: the rooms stretch to fill a small gap.

    A large gap (over half the rooms' length) is left open instead: an
    ``["open", gap]`` entry at index ``at`` (``len(row)``: at the end) that
    the layout skips, so the yard fills the notch (an L-shaped outline).
    ``row`` is a list of ``[kind, width]``, changed in place.
    """
    total = sum(w for _, w in row)
    gap = length - total
    if gap > 0.5 * total and gap >= _MIN_OPEN:
        row.insert(at, ["open", gap])
    else:
        for r in row:
            r[1] *= length / total


def _public_row(rng, prog, full_west, mudroom) -> tuple[list[str], list[str]]:
    """The public row (kitchen – dining – living, office, foyer) and the office's other-row place.

    With a mudroom the kitchen ends the row, next to the mudroom and garage.
    """
    public = [t for t in ("living_room", "dining_room", "kitchen") if prog[t] and t != full_west]
    if not mudroom and rng.random() < 0.5:
        public.reverse()
    north, south = list(public), []
    if prog["office"]:
        u = rng.random()
        if full_west and u < 0.6:
            # Both rows start beside the full-depth living room.
            (north if rng.random() < 0.5 else south).insert(0, "office")
        elif "living_room" in north and u < 0.6:
            north.insert(0 if north[0] == "living_room" else len(north), "office")
        elif u < 0.9 and not mudroom:
            north.insert(0 if north[0] == "kitchen" else len(north), "office")
        else:
            south.append("office")
    return north, south


def floor_plan(rng: np.random.Generator, prog: dict[str, int]) -> Plan:
    """Lays the rooms of a programme out as rectangles (see the module docstring).

    Args:
      rng: the house's generator.
      prog: the programme (:func:`leaps_mj.world.generator.sample_programme`).

    Returns:
      the :class:`Plan`.
    """
    private = _private_wing(rng, prog)
    big = len(private) >= _L_MIN_PRIVATE and prog["bedroom"] >= 1
    shape = "L" if big and rng.random() < _L_PLAN_P else "corridor"
    full_west = ("living_room" if shape == "corridor" and prog["living_room"] and rng.random() < 0.5
                 else None)
    mudroom = bool(prog["mudroom"])
    north, south = _public_row(rng, prog, full_west, mudroom)
    # A hallway with no outside end (a full-depth living room or the bedroom
    # wing at one end, the garage at the other) gets an entry foyer.
    # With a mudroom the foyer stays before the kitchen, which meets the mudroom.
    if (full_west or shape == "L") and prog["garage"]:
        lo, hi = (0, len(north)) if mudroom else (1, len(north) + 1)
        north.insert(int(rng.integers(lo, hi)), "foyer")

    def width(kind):
        return float(rng.uniform(*_WIDTH[kind]))

    # The bedroom wing of an L plan takes two thirds of the private rooms
    # (at least two); the rest share the main wing's rows.
    n_arm = max(2, -(-2 * len(private) // 3)) if shape == "L" else 0
    arm = [[t, width(t)] for t in private[len(private) - n_arm:]]
    rows_private = [[t, width(t)] for t in private[: len(private) - n_arm]]
    north = [[t, width(t)] for t in north]
    south = [[t, width(t)] for t in south]
    if shape == "L" and not south and not rows_private:
        rows_private = [arm.pop(0)] if len(arm) > 2 else [["closet", width("closet")]]
    # Split the private rooms to balance the row lengths; in the public row
    # they go at the far end from the garage when a mudroom must meet it.
    lead = []
    for r in rows_private:
        if sum(w for _, w in north) + sum(w for _, w in lead) <= sum(w for _, w in south):
            (lead if mudroom else north).append(r)
        else:
            south.append(r)
    north = lead + north
    if mudroom:
        north.append(["mudroom", width("mudroom")])
    if not north:
        north = [["closet", width("closet")]]
    if not south:
        south = [["closet", width("closet")]]
    row_len = max(sum(w for _, w in north), sum(w for _, w in south))
    _fit(north, row_len, at=0 if mudroom else len(north))
    _fit(south, row_len, at=len(south))
    public_north = rng.random() >= 0.5
    if not public_north:
        north, south = south, north

    depth_s = float(rng.uniform(*_ROW_DEPTH))
    depth_n = float(rng.uniform(*_ROW_DEPTH))
    hall = float(rng.uniform(*_HALL_WIDTH))
    depth = depth_s + hall + depth_n
    out: list[tuple[str, tuple]] = []
    hallways = [0]
    x = 0.0
    west_room = None
    if full_west:
        w = width(full_west) + 0.5
        west_room = (full_west, (0.0, 0.0, w, depth))
        x = w
    elif shape == "L":
        wing = (float(rng.uniform(*_ROW_DEPTH)), float(rng.uniform(*_HALL_WIDTH)))
        x = sum(wing)
    out.append(("hallway", (x, depth_s, x + row_len, depth_s + hall)))
    if west_room:
        out.append(west_room)
    # Half of the houses have a stepped outline: some rooms are shallower
    # than their row, their outer wall set back (the yard fills the notch).
    # Under the bedroom wing of an L plan the north row keeps its depth.
    stepped = rng.random() < 0.5
    foyer = None
    for row, y0, y1, outer in ((south, 0.0, depth_s, 0), (north, depth_s + hall, depth, 1)):
        cx = x
        for kind, w in row:
            rect = [cx, y0, cx + w, y1]
            max_cut = min(1.2, y1 - y0 - 3.0)
            if stepped and max_cut >= 0.4 and not (shape == "L" and outer == 1) and rng.random() < 0.4:
                cut = float(rng.uniform(0.4, max_cut))
                rect[1 + 2 * outer] += cut if outer == 0 else -cut
            cx += w
            if kind == "open":
                continue
            if kind == "foyer":
                foyer = len(out)
            out.append((kind, tuple(rect)))
    if shape == "L":
        hallways.append(len(out))
        out += _bedroom_wing(rng, arm, wing, depth)
    x_end = x + row_len
    if prog["garage"]:
        out.append(("garage", (x_end, 0.0, x_end + width("garage"), depth)))
    # Mirror at random so the garage, the living room and the bedroom wing
    # take either end and either side.
    if rng.random() < 0.5:
        total = max(r[2] for _, r in out)
        out = [(t, (total - r[2], r[1], total - r[0], r[3])) for t, r in out]
    if shape == "L" and rng.random() < 0.5:
        total = max(r[3] for _, r in out)
        out = [(t, (r[0], total - r[3], r[2], total - r[1])) for t, r in out]
    out = [(t, tuple(round(v, 2) for v in r)) for t, r in out]
    return Plan(rooms=tuple(out), hallways=tuple(hallways), foyer=foyer, shape=shape)


def _bedroom_wing(rng, arm: list[list], wing: tuple[float, float], depth: float) -> list[tuple[str, tuple]]:
    """The second hallway and the bedroom wing of an L plan, west of the main wing.

    The hallway runs north from the south edge of the house along the main
    wing's west end (so it meets the main hallway's end) and on past the main
    wing; the west column of rooms runs beside it from the south edge, the
    east column sits above the main wing's north row.

    Args:
      rng: the house's generator.
      arm: ``[kind, width]`` of the wing's rooms (width along the hallway).
      wing: (depth of the west column, width of the hallway); their sum is
        the main wing's west edge.
      depth: the main wing's depth.

    Returns:
      the hallway first, then the rooms, as (kind, rect).
    """
    depth_w, hall = wing
    x_main = depth_w + hall
    depth_e = float(rng.uniform(*_ROW_DEPTH))
    west, east = [], []
    for r in arm:
        # The west column starts ``depth`` lower: balance the columns' tops.
        if sum(w for _, w in west) - depth <= sum(w for _, w in east):
            west.append(r)
        else:
            east.append(r)
    if not east:
        east.append(west.pop())
    length = max(sum(w for _, w in east), sum(w for _, w in west) - depth, _MIN_OPEN)
    _fit(west, depth + length, at=len(west))
    _fit(east, length, at=len(east))
    out = [("hallway", (depth_w, 0.0, x_main, depth + length))]
    for column, x0, x1, y in ((west, 0.0, depth_w, 0.0), (east, x_main, x_main + depth_e, depth)):
        for kind, w in column:
            if kind != "open":
                out.append((kind, (x0, y, x1, y + w)))
            y += w
    return out
