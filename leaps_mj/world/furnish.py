"""Stage 4 of house generation: furniture from the catalogue, placed room by room.

Items of ``assets/furniture.json`` (boxes, cylinders, ellipsoids) go against
walls or free-standing, never in a door's clearance zone nor through a wall;
hanging items (wall cabinets) only above low ones; trees in the yard. A room
whose required items do not fit raises :class:`NoRoom`, and the generator
(:func:`leaps_mj.world.generator.generate`) redraws the layout.
"""

from __future__ import annotations

import functools
import json

import numpy as np

from leaps_mj.world import rooms
from leaps_mj.world.houses import ASSETS_DIR, Geom, Item

#: Lowest height of hanging items (wall cabinets) in the catalogue.
_HANGING_Z = 1.45


class NoRoom(Exception):
    """A required item found no place in its room (the layout is redrawn)."""


@functools.lru_cache(maxsize=1)
def catalogue() -> dict:
    """The furniture catalogue ``assets/furniture.json``."""
    with open(ASSETS_DIR / "furniture.json") as f:
        return json.load(f)


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


def furnish(rng, house_rooms, doors, walls, lot):
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
                    raise NoRoom(f"no room for required {key} in {room.name}")
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
