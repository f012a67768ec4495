"""Room types, object classes, segmentation classes and the action set.

These tables are the contract shared by the house generator, the environment,
the semantic model and the agents. The room order and the "see" objects follow
the original LEAPS release (House3D RoomNav), so priors and results line up
with the paper's.
"""

import functools
import json
import pathlib

import numpy as np

#: The package folder and its shipped data (checkpoints, priors, the reference prior).
PACKAGE_DIR = pathlib.Path(__file__).resolve().parents[1]
DATA_DIR = PACKAGE_DIR / "data"
#: The repository root (canonical datasets, furniture catalogue, agent MJCF).
REPO_DIR = PACKAGE_DIR.parent

#: The K = 8 target room types, in the order of the original release.
ROOM_TYPES = (
    "outdoor",
    "kitchen",
    "dining_room",
    "living_room",
    "bathroom",
    "bedroom",
    "office",
    "garage",
)
#: Pseudo room type for indoor space of no target type (hallways, closets,
#: laundry). Its semantic bits are all zero; it is node K of the semantic graph.
INDOOR = "indoor"
#: Room types plus the untyped indoor node: the nodes of the semantic graph.
GRAPH_NODES = ROOM_TYPES + (INDOOR,)
NUM_ROOM_TYPES = len(ROOM_TYPES)


def room_index(room_type: str) -> int:
    """Index of a room type (or ``indoor``) in :data:`GRAPH_NODES`.

    Raises:
      ValueError: naming the unknown type and the known ones.
    """
    try:
        return GRAPH_NODES.index(room_type)
    except ValueError:
        raise ValueError(
            f"unknown room type {room_type!r}; expected one of {list(GRAPH_NODES)}"
        ) from None


def target_onehot(target: str) -> np.ndarray:
    """The ``target`` observation of a graph node: (K,) uint8 one-hot, all zero for ``indoor``.

    Raises:
      ValueError: for an unknown room type.
    """
    onehot = np.zeros(NUM_ROOM_TYPES, dtype=np.uint8)
    index = room_index(target)
    if index < NUM_ROOM_TYPES:
        onehot[index] = 1
    return onehot


@functools.lru_cache(maxsize=None)
def reference() -> dict:
    """The original release's learned prior, room frequencies and see-objects."""
    with open(DATA_DIR / "leaps_release_prior.json") as f:
        return json.load(f)


def reference_prior() -> np.ndarray:
    """The 9x9 room-connectivity prior learned on SUNCG (diagonal meaningless)."""
    ref = reference()
    assert tuple(ref["rooms"]) == GRAPH_NODES, ref["rooms"]
    return np.asarray(ref["prior"], dtype=np.float64)


#: Object classes whose pixels count toward the "see" test, per target room.
SEE_OBJECTS = {
    room: tuple(classes)
    for room, classes in reference()["see_objects"].items()
    if room != "note"
}

#: Segmentation classes. 0 is empty space (sky / nothing hit); structural
#: classes follow, then furniture classes (the see-objects first, then décor).
STRUCTURE_CLASSES = ("empty", "wall", "floor", "ceiling", "door", "fence", "agent")
FURNITURE_CLASSES = (
    # see-objects of the original release
    "kitchen_appliance",
    "hanging_kitchen_cabinet",
    "kitchen_set",
    "kitchenware",
    "kitchen_cabinet",
    "sink",
    "sofa",
    "television",
    "chair",
    "table_and_chair",
    "table",
    "dresser",
    "bed",
    "wardrobe_cabinet",
    "shower",
    "toilet",
    "bathtub",
    "bathroom_stuff",
    "computer",
    "desk",
    "workplace",
    "vehicle",
    "garage_door",
    # décor that counts for no room
    "shelving",
    "plant",
    "rug",
    "washer",
    "tree",
)
SEG_CLASSES = STRUCTURE_CLASSES + FURNITURE_CLASSES
NUM_SEG_CLASSES = len(SEG_CLASSES)


def seg_class_index(name: str) -> int:
    """Index of a segmentation class.

    Raises:
      ValueError: naming the unknown class.
    """
    try:
        return SEG_CLASSES.index(name)
    except ValueError:
        raise ValueError(
            f"unknown object class {name!r}; expected one of {list(SEG_CLASSES)}"
        ) from None


assert all(c in FURNITURE_CLASSES for v in SEE_OBJECTS.values() for c in v)

#: The 9 discrete actions: (name, forward metres, left metres, yaw degrees).
#: Step sizes follow House3D's RoomNav (move 0.5 m, turn 30°, small variants).
ACTIONS = (
    ("forward", 0.5, 0.0, 0.0),
    ("left_forward", 0.5 * np.cos(np.pi / 4), 0.5 * np.sin(np.pi / 4), 0.0),
    ("right_forward", 0.5 * np.cos(np.pi / 4), -0.5 * np.sin(np.pi / 4), 0.0),
    ("left_rotate", 0.0, 0.0, 30.0),
    ("right_rotate", 0.0, 0.0, -30.0),
    ("small_forward", 0.1, 0.0, 0.0),
    ("small_left_rotate", 0.0, 0.0, 15.0),
    ("small_right_rotate", 0.0, 0.0, -15.0),
    ("stay", 0.0, 0.0, 0.0),
)
NUM_ACTIONS = len(ACTIONS)
ACTION_NAMES = tuple(a[0] for a in ACTIONS)

#: Geometry shared by generator and environment (metres).
AGENT_RADIUS = 0.2
AGENT_CAMERA_HEIGHT = 1.2
WALL_HEIGHT = 2.6
WALL_THICKNESS = 0.1
DOOR_WIDTH = 1.0
