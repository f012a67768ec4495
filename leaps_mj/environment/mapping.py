"""An egocentric top-down map built from the agent's own frames and pose.

The learners of sessions 4–7 (docs/training.md) failed where the way on
depends on memory — which rooms were looked into, which doors were passed,
where the target's furniture was glimpsed — and a CNN+LSTM imitating a teacher
from 0.2–0.3 M samples did not learn to keep it. :class:`EgoMapper` keeps that
memory explicitly, as the mapping modules of modular navigation agents do: each
frame's depth is projected through the camera model into a top-down grid
anchored at the run's first pose, the segmentation labels the projected points,
and every step the grid is read out as a window centred on the agent and turned
to its heading. It uses only what the agent senses (segmentation, depth and its
pose, the ``pose`` observation), so a policy reading the map still acts on
observations alone; it is rebuilt from scratch at each :meth:`EgoMapper.reset`.

Channels of the map (uint8, 1 where the cell holds it):

0. ``obstacle``: wall, fence or furniture seen between :data:`OBSTACLE_BAND` metres high;
1. ``floor``: floor seen (free space);
2. ``door``: a door lintel seen (the doorways);
3. ``target``: one of the target's see-objects (none for ``indoor``; none for ``outdoor`` either, unless
   the mapper marks its :data:`CUES`, fences and trees);
4. ``furniture``: any other furniture;
5. ``visited``: cells the agent stood in.

With ``semantic``, one more channel per room type that has see-objects (:data:`SEMANTIC`): its
see-objects, whatever the target. Several types share classes (a table is the dining room's, the living
room's and the office's), so a mapped table alone does not say which room it stands in; what else
stands around it (a sofa, a computer) does, and these channels show it.

:meth:`EgoMapper.context` reads the same channels out over a window twice as wide at half
the resolution (:data:`CONTEXT_CELL`), for what was mapped beyond the 4 m around the agent.

Beside them it keeps a ``blocked`` layer for planning on the map
(:mod:`leaps_mj.environment.map_navigation`): every non-floor, non-door point
within :data:`OBSTACLE_BAND`, furniture included, and cells the agent bumped into.
"""

from __future__ import annotations

import math

import numpy as np

from leaps_mj.world import rooms

#: The map's channels, in order.
CHANNELS = ("obstacle", "floor", "door", "target", "furniture", "visited")
#: Side of a map cell (metres).
CELL = 0.25
#: Cells on each side of the egocentric window (8 m at 0.25 m; the agent at its centre, facing up).
WINDOW = 32
#: Cells on each side of the allocentric grid the frames are projected into (32 m, centred on the first pose).
GRID = 128
#: Side of a cell of :meth:`EgoMapper.context`'s coarse window (16 m across at WINDOW cells).
CONTEXT_CELL = 2 * CELL
#: Classes that mark a node on the map where it has no see-objects (with ``cues``): an outdoor
#: area is fenced and has the trees.
CUES = {"outdoor": ("fence", "tree")}
#: Room types marked in a channel of their own by a ``semantic`` map, in channel order after CHANNELS.
SEMANTIC = tuple(node for node in rooms.GRAPH_NODES if rooms.SEE_OBJECTS.get(node))
#: Vertical field of view of the agent's camera (degrees; ``assets/agent.xml``).
CAMERA_FOVY = 60.0
#: Points farther than this (metres along the view axis) are not mapped: at 40x30 they are too coarse.
MAX_RANGE = 8.0
#: Heights (metres) between which a non-floor point counts as an obstacle.
OBSTACLE_BAND = (0.05, 2.0)

_FLOOR = rooms.seg_class_index("floor")
_DOOR = rooms.seg_class_index("door")
_UNMAPPED = [rooms.seg_class_index(c) for c in ("empty", "ceiling", "agent")]
_FURNITURE = [rooms.seg_class_index(c) for c in rooms.FURNITURE_CLASSES]


def _class_channels(target: str, cues: bool) -> np.ndarray:
    """Channel of each segmentation class's points (-1: not mapped; obstacles are decided by height)."""
    rooms.room_index(target)
    table = np.full(rooms.NUM_SEG_CLASSES, CHANNELS.index("obstacle"), np.int64)
    table[_FURNITURE] = CHANNELS.index("furniture")
    marks = rooms.SEE_OBJECTS.get(target, ()) + (CUES.get(target, ()) if cues else ())
    table[[rooms.seg_class_index(c) for c in marks]] = CHANNELS.index("target")
    table[_FLOOR] = CHANNELS.index("floor")
    table[_DOOR] = CHANNELS.index("door")
    table[_UNMAPPED] = -1
    return table


def num_channels(semantic: bool) -> int:
    """Channels of a map: :data:`CHANNELS`, and with ``semantic`` one per room type of :data:`SEMANTIC`."""
    return len(CHANNELS) + (len(SEMANTIC) if semantic else 0)


def _semantic_marks() -> np.ndarray:
    """(classes, len(SEMANTIC)) bool: which room types' see-objects each segmentation class is."""
    marks = np.zeros((rooms.NUM_SEG_CLASSES, len(SEMANTIC)), bool)
    for k, node in enumerate(SEMANTIC):
        marks[[rooms.seg_class_index(c) for c in rooms.SEE_OBJECTS[node]], k] = True
    return marks


class EgoMapper:
    """Accumulates frames into a top-down map and reads it out around the agent.

    Args:
      target: The graph node the run heads for (its see-objects fill the
        ``target`` channel).
      width, height: Resolution of the frames it is given.
      cues: Also mark the target's :data:`CUES` in the ``target`` channel.
      semantic: Also mark each room type's see-objects in a channel of its own (:data:`SEMANTIC`).

    Raises:
      ValueError: for an unknown target or a non-positive resolution.
    """

    def __init__(self, target: str, width: int, height: int, cues: bool = False, semantic: bool = False):
        if width < 1 or height < 1:
            raise ValueError(f"frame size {width}x{height}: expected positive width and height")
        self.target = target
        self.width, self.height = width, height
        self._channel_of = _class_channels(target, cues)
        focal = (height / 2) / math.tan(math.radians(CAMERA_FOVY) / 2)
        cols = (np.arange(width) + 0.5 - width / 2) / focal
        rows = (height / 2 - np.arange(height) - 0.5) / focal
        self._right, self._up = np.meshgrid(cols, rows)  # per metre of depth, (H, W)
        # Window cell (i, j) lies (WINDOW/2 - i - 0.5) cells ahead of the agent and (WINDOW/2 - j - 0.5) to its left.
        offsets = (WINDOW / 2 - np.arange(WINDOW) - 0.5) * CELL
        self._ahead, self._left = np.meshgrid(offsets, offsets, indexing="ij")
        # The coarse window's cells, each sampled at the centres of the 2 x 2 fine cells it covers.
        coarse = (WINDOW / 2 - np.arange(WINDOW) - 0.5) * CONTEXT_CELL
        self._context = [np.meshgrid(coarse + da, coarse + dl, indexing="ij")
                         for da in (-CELL / 2, CELL / 2) for dl in (-CELL / 2, CELL / 2)]
        self._marks = _semantic_marks() if semantic else None
        self._grid = np.zeros((num_channels(semantic), GRID, GRID), np.uint8)
        self.blocked = np.zeros((GRID, GRID), bool)
        self._origin: np.ndarray | None = None

    def reset(self) -> None:
        """Forgets the map; the next :meth:`update` anchors a new one at its pose."""
        self._grid[:] = 0
        self.blocked[:] = False
        self._origin = None

    @property
    def grid(self) -> np.ndarray:
        """The allocentric map (channels, GRID, GRID): row ``r``, column ``c`` is the cell
        ``(c - GRID/2) * CELL`` east and ``(r - GRID/2) * CELL`` north of the first pose."""
        return self._grid

    def cells(self, x, y) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Grid rows and columns of world points (arrays), and which of them fall inside the grid.

        Raises:
          ValueError: before the first :meth:`update` (the grid has no anchor yet).
        """
        if self._origin is None:
            raise ValueError("the map has no anchor yet: call update() first")
        x, y = np.asarray(x, np.float64), np.asarray(y, np.float64)
        col = np.floor((x - self._origin[0]) / CELL).astype(np.int64) + GRID // 2
        row = np.floor((y - self._origin[1]) / CELL).astype(np.int64) + GRID // 2
        inside = (row >= 0) & (row < GRID) & (col >= 0) & (col < GRID)
        return row, col, inside

    def world(self, row, col) -> tuple[np.ndarray, np.ndarray]:
        """World (x, y) of grid cells' centres."""
        x = self._origin[0] + (np.asarray(col) - GRID // 2 + 0.5) * CELL
        y = self._origin[1] + (np.asarray(row) - GRID // 2 + 0.5) * CELL
        return x, y

    def window_world(self, pose) -> tuple[np.ndarray, np.ndarray]:
        """World (x, y) of the centres of the egocentric window's cells around ``pose``, each (WINDOW, WINDOW)."""
        px, py, yaw = (float(v) for v in pose)
        cos, sin = math.cos(yaw), math.sin(yaw)
        return px + self._ahead * cos - self._left * sin, py + self._ahead * sin + self._left * cos

    def context(self, pose) -> np.ndarray:
        """The map around ``pose`` over a window of WINDOW cells of :data:`CONTEXT_CELL` (16 m across),
        oriented as :meth:`update`'s: (channels, WINDOW, WINDOW) uint8, a coarse cell 1 where
        any of the fine cells it covers is."""
        px, py, yaw = (float(v) for v in pose)
        cos, sin = math.cos(yaw), math.sin(yaw)
        window = np.zeros((len(self._grid), WINDOW, WINDOW), np.uint8)
        for ahead, left in self._context:
            row, col, inside = self.cells(px + ahead * cos - left * sin, py + ahead * sin + left * cos)
            window[:, inside] |= self._grid[:, row[inside], col[inside]]
        return window

    def window_cell(self, pose, x: float, y: float) -> tuple[int, int]:
        """The egocentric window cell (row, column) holding world point (x, y) seen from ``pose``,
        clipped to the window's border when the point lies outside it."""
        px, py, yaw = (float(v) for v in pose)
        dx, dy = x - px, y - py
        ahead = dx * math.cos(yaw) + dy * math.sin(yaw)
        left = -dx * math.sin(yaw) + dy * math.cos(yaw)
        row = int(np.clip(math.floor(WINDOW / 2 - ahead / CELL), 0, WINDOW - 1))
        col = int(np.clip(math.floor(WINDOW / 2 - left / CELL), 0, WINDOW - 1))
        return row, col

    def block(self, x: float, y: float) -> None:
        """Marks the cell holding world point (x, y) as blocked (where the agent bumped into something)."""
        row, col, inside = self.cells(x, y)
        if inside:
            self.blocked[row, col] = True

    def update(self, segmentation: np.ndarray, depth: np.ndarray, pose: np.ndarray) -> np.ndarray:
        """Adds a frame seen from ``pose`` and returns the map around the agent.

        Args:
          segmentation: (height, width) class ids.
          depth: (height, width) metres along the view axis.
          pose: (x, y, yaw radians) of the agent, as the ``pose`` observation.

        Returns:
          (channels, WINDOW, WINDOW) uint8 (:func:`num_channels`): row 0 is ahead of the agent,
          column 0 to its left; the agent stands between the four centre cells.

        Raises:
          ValueError: for frames of another size than the mapper's.
        """
        seg, depth = np.asarray(segmentation), np.asarray(depth, np.float64)
        if seg.shape != (self.height, self.width) or depth.shape != seg.shape:
            raise ValueError(f"frames of shapes {seg.shape} and {depth.shape}; expected "
                             f"(height, width) = ({self.height}, {self.width})")
        px, py, yaw = (float(v) for v in pose)
        if self._origin is None:
            self._origin = np.array([px, py])
        cos, sin = math.cos(yaw), math.sin(yaw)
        channel = self._channel_of[seg]
        z = rooms.AGENT_CAMERA_HEIGHT + self._up * depth
        obstacle = CHANNELS.index("obstacle")
        low, high = OBSTACLE_BAND
        keep = (channel >= 0) & (depth <= MAX_RANGE) & ((channel != obstacle) | ((z >= low) & (z <= high)))
        d, right, channel = depth[keep], self._right[keep] * depth[keep], channel[keep]
        row, col, inside = self.cells(px + d * cos + right * sin, py + d * sin - right * cos)
        self._grid[channel[inside], row[inside], col[inside]] = 1
        if self._marks is not None:
            marks = self._marks[seg[keep][inside]]
            for k in range(marks.shape[1]):
                self._grid[len(CHANNELS) + k, row[inside][marks[:, k]], col[inside][marks[:, k]]] = 1
        solid = inside & (channel != CHANNELS.index("floor")) & (channel != CHANNELS.index("door")) \
            & (z[keep] >= low) & (z[keep] <= high)
        self.blocked[row[solid], col[solid]] = True
        here_row, here_col, here_inside = self.cells(px, py)
        if here_inside:
            self._grid[CHANNELS.index("visited"), here_row, here_col] = 1
        row, col, inside = self.cells(*self.window_world(pose))
        window = np.zeros((len(self._grid), WINDOW, WINDOW), np.uint8)
        window[:, inside] = self._grid[:, row[inside], col[inside]]
        return window
