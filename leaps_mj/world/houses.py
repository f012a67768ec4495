"""Houses as plain data: rooms, doors, walls and labelled furniture geoms.

A :class:`House` is what the generator (:mod:`leaps_mj.world.generator`)
produces and what every later stage reads: it serialises to the JSON written
beside each MJCF file (``to_json`` / ``from_json`` / ``load``) and is all the
environment needs besides the compiled model. Keeping the data model apart
from the generator lets the navigation grid, MJCF writer and drawing code
depend on houses without depending on how they are made.
"""

from __future__ import annotations

import dataclasses
import json
import pathlib

from leaps_mj.world import rooms

ASSETS_DIR = rooms.REPO_DIR / "assets"
FORMAT_VERSION = 1


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

    def plan_lengths(self, target: str) -> dict[int, int]:
        """Fewest room-to-room hops (door to door) from each room to a room of type ``target``.

        Returns:
          room id → hops (0 in a ``target`` room); rooms that cannot reach one
          are left out (and every room is, if the house has no such room).

        Raises:
          ValueError: if ``target`` is not a graph node (room type or ``indoor``).
        """
        if target not in rooms.GRAPH_NODES:
            raise ValueError(f"unknown room type {target!r}; expected one of {list(rooms.GRAPH_NODES)}")
        adj: dict[int, set[int]] = {r.id: set() for r in self.rooms}
        for a, b in self.connectivity():
            adj[a].add(b)
            adj[b].add(a)
        hops = {r.id: 0 for r in self.rooms if r.type == target}
        frontier = list(hops)
        while frontier:
            nxt = []
            for i in frontier:
                for j in sorted(adj[i] - hops.keys()):
                    hops[j] = hops[i] + 1
                    nxt.append(j)
            frontier = nxt
        return hops

    def diameter(self) -> int:
        """The longest optimal plan in the house: the most hops from any room
        to the nearest room of a target type it contains (0 if it has none)."""
        longest = 0
        for target in set(self.room_types) & set(rooms.ROOM_TYPES):
            longest = max([longest, *self.plan_lengths(target).values()])
        return longest

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
