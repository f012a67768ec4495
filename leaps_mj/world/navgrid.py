"""Navigation grid of a house: free space, room labels and geodesic distances.

The floor of the lot is rasterised at ``cell`` metres; a cell is free when a
cylinder of the agent's radius centred on it touches no wall or furniture
footprint (a Euclidean distance transform of the obstacle raster). Geodesic
distances are shortest 8-connected paths through free cells (Dijkstra, in C
through :mod:`scipy.sparse.csgraph`), so they agree with what an agent of that
radius can actually travel.
"""

from __future__ import annotations

import functools
import math

import numpy as np
import scipy.ndimage
import scipy.sparse
import scipy.sparse.csgraph

from leaps_mj.world import houses, rooms


class Unreachable(Exception):
    """Some room of a house cannot be reached by the agent."""


class NavGrid:
    """Occupancy, room labels and geodesics of one house.

    Attributes:
      cell: cell size in metres.
      origin: world (x, y) of cell (0, 0)'s lower-left corner.
      free: bool (nx, ny) array, True where the agent's centre may be.
      room_id: int (nx, ny) array, the room of each cell's centre (-1: none);
        indoor rooms take precedence over the outdoor lot they sit in.
    """

    def __init__(self, house: houses.House, cell: float = 0.1, radius: float = rooms.AGENT_RADIUS):
        self.house = house
        self.cell = cell
        self.radius = radius
        x0, y0, x1, y1 = house.lot
        pad = 0.5
        self.origin = np.array([x0 - pad, y0 - pad])
        self.shape = (int(np.ceil((x1 - x0 + 2 * pad) / cell)), int(np.ceil((y1 - y0 + 2 * pad) / cell)))
        blocked = np.zeros(self.shape, dtype=bool)
        for rect in house.obstacles():
            i0, j0, i1, j1 = self._rect_cells(rect)
            blocked[i0:i1, j0:j1] = True
        clearance = scipy.ndimage.distance_transform_edt(~blocked) * cell
        # A cell centre is at most half a cell from the obstacle raster's edge.
        self.room_id = self._label_rooms()
        fits = (clearance >= radius + 0.5 * cell) & (self.room_id >= 0)
        # Keep the largest connected region: pockets behind furniture are not
        # places an episode may start.
        labels, _ = scipy.ndimage.label(fits, structure=np.ones((3, 3)))
        counts = np.bincount(labels.ravel())
        counts[0] = 0
        self.free = labels == counts.argmax()

    def _rect_cells(self, rect):
        x0, y0, x1, y1 = rect
        i0 = int(np.floor((x0 - self.origin[0]) / self.cell))
        j0 = int(np.floor((y0 - self.origin[1]) / self.cell))
        i1 = int(np.ceil((x1 - self.origin[0]) / self.cell))
        j1 = int(np.ceil((y1 - self.origin[1]) / self.cell))
        return max(i0, 0), max(j0, 0), max(i1, 0), max(j1, 0)

    def _label_rooms(self):
        label = np.full(self.shape, -1, dtype=np.int32)
        xs, ys = self.cell_centers()
        for r in sorted(self.house.rooms, key=lambda r: r.type != "outdoor"):
            x0, y0, x1, y1 = r.rect
            inside = (xs >= x0) & (xs < x1) & (ys >= y0) & (ys < y1)
            label[inside] = r.id
        return label

    def cell_centers(self):
        """World x and y of every cell centre, as two (nx, ny) arrays."""
        i = np.arange(self.shape[0])
        j = np.arange(self.shape[1])
        xs = self.origin[0] + (i[:, None] + 0.5) * self.cell
        ys = self.origin[1] + (j[None, :] + 0.5) * self.cell
        return np.broadcast_to(xs, self.shape), np.broadcast_to(ys, self.shape)

    def to_cell(self, xy) -> tuple[int, int]:
        """Grid index of a world point (clipped to the grid).

        Plain float arithmetic: this runs several times per environment step.
        """
        i = math.floor((float(xy[0]) - self.origin[0]) / self.cell)
        j = math.floor((float(xy[1]) - self.origin[1]) / self.cell)
        return min(max(i, 0), self.shape[0] - 1), min(max(j, 0), self.shape[1] - 1)

    def to_world(self, ij) -> np.ndarray:
        """World (x, y) of a cell centre."""
        return self.origin + (np.asarray(ij, dtype=float) + 0.5) * self.cell

    @functools.cached_property
    def _graph(self):
        """Sparse 8-connected graph over free cells (edge weight in metres).

        A diagonal step needs both orthogonal neighbours free: no corner cutting.
        """
        nx, ny = self.shape
        padded = np.pad(self.free, 1)

        def shifted(di, dj):
            return padded[1 + di: 1 + di + nx, 1 + dj: 1 + dj + ny]

        idx = np.arange(nx * ny).reshape(nx, ny)
        rows, cols, weights = [], [], []
        for di, dj in ((1, 0), (0, 1), (1, 1), (1, -1)):
            ok = self.free & shifted(di, dj)
            if di and dj:
                ok &= shifted(di, 0) & shifted(0, dj)
            src = idx[ok]
            rows.append(src)
            cols.append(src + di * ny + dj)
            weights.append(np.full(src.shape, self.cell * np.hypot(di, dj)))
        rows, cols, weights = map(np.concatenate, (rows, cols, weights))
        return scipy.sparse.csr_matrix((weights, (rows, cols)), shape=(nx * ny, nx * ny))

    def distance_from(self, mask: np.ndarray) -> np.ndarray:
        """Geodesic metres from every cell to the nearest free cell of ``mask``.

        Unreachable cells get ``inf``.
        """
        sources = np.flatnonzero((mask & self.free).ravel())
        if sources.size == 0:
            return np.full(self.shape, np.inf)
        dist = scipy.sparse.csgraph.dijkstra(self._graph, directed=False, indices=sources, min_only=True)
        return dist.reshape(self.shape)

    def room_mask(self, room_type: str) -> np.ndarray:
        """Free cells inside any room of ``room_type``."""
        rooms.room_index(room_type)
        ids = [r.id for r in self.house.rooms if r.type == room_type]
        return np.isin(self.room_id, ids) & self.free

    @functools.lru_cache(maxsize=16)
    def distance_to_type(self, room_type: str) -> np.ndarray:
        """Geodesic metres from every cell to the nearest room of ``room_type``."""
        return self.distance_from(self.room_mask(room_type))

    def check_reachable(self, min_cells: int = 20) -> None:
        """Checks every room has at least ``min_cells`` of connected free floor.

        Raises:
          Unreachable: naming the first room that is not reachable.
        """
        for r in self.house.rooms:
            n = int(np.sum(self.free & (self.room_id == r.id)))
            if n < min_cells:
                raise Unreachable(f"room {r.name} has {n} reachable cells (< {min_cells})")
