"""Frozen architecture configs of the networks in :mod:`leaps_mj.learning.nets`, validated on construction.

Apart from the networks so that the configs (what a checkpoint stores and a
trainer's config builds) can be read without the layers, and to keep each
module small. :mod:`leaps_mj.learning.nets` re-exports them.
"""

import dataclasses
import math
from typing import Any

from leaps_mj.environment import mapping
from leaps_mj.world import rooms


def _check_positive(name: str, value: Any) -> None:
    if isinstance(value, bool) or not isinstance(value, int) or value <= 0:
        raise ValueError(f"{name} must be a positive int, got {value!r}")


def _check_positive_tuple(name: str, values: tuple) -> None:
    if not values:
        raise ValueError(f"{name} must not be empty")
    for i, value in enumerate(values):
        _check_positive(f"{name}[{i}]", value)


def _check_pixels(config: Any) -> None:
    """Checks the fields shared by the pixel-input configs."""
    _check_positive("width", config.width)
    _check_positive("height", config.height)
    _check_positive("num_classes", config.num_classes)
    if isinstance(config.seg_embed, bool) or not isinstance(config.seg_embed, int) or config.seg_embed < 0:
        raise ValueError(f"seg_embed must be an int >= 0 (0 = one-hot), got {config.seg_embed!r}")
    if not config.max_depth > 0 or not math.isfinite(config.max_depth):
        raise ValueError(f"max_depth must be a positive finite number of metres, got {config.max_depth!r}")


@dataclasses.dataclass(frozen=True)
class PolicyConfig:
    """Architecture of the CNN+LSTM actor-critic (defaults: the paper's).

    Attributes:
      width: Frame width in pixels (paper 120).
      height: Frame height in pixels (paper 90).
      conv_channels: Output channels of each conv layer.
      kernel: Conv kernel size; padding ``kernel // 2`` keeps small frames usable.
      stride: Conv stride of every layer.
      hidden: Units of the linear layer after the conv stack.
      lstm: LSTM units.
      seg_embed: Segmentation encoding. 0 feeds a one-hot plane per class;
        a positive value feeds a learned ``nn.Embedding`` of that dimension.
        The default 8 is equivalent to a 1x1 conv on the one-hot planes but
        makes the first conv 4x cheaper than one-hot over 35 classes.
      max_depth: Depth is clipped to ``[0, max_depth]`` metres and scaled to [0, 1].
      use_semantic: The semantic-augmented policy μ_s: concatenate the
        room-type bits and the target one-hot to the features before the LSTM.
      target_input: One network for every graph node: concatenate the
        node's one-hot (``node``, K + 1 floats) to the LSTM input and to the
        heads' input. Pixels only otherwise, as μ(θ) must be.
      prev_action: Also feed the action taken at the previous step
        (``prev_action``, an int, -1 at an episode's first step) to the LSTM
        as a one-hot, so the policy can keep a turn going instead of
        dithering between left and right when both look alike.
      aux: Add auxiliary heads, read only by training losses: which graph
        nodes' rooms each of :data:`VIEW_COLUMNS` vertical strips of the
        frame shows (from the frame features), the room-type bits of where
        the agent stands and the geodesic distance to the target (from the
        LSTM state).
      map_input: Also read the egocentric top-down map the agent builds from
        its own frames and pose (``egomap``,
        :class:`leaps_mj.environment.mapping.EgoMapper`) through a small CNN
        whose features join the LSTM input and the heads' input: memory of
        where the target's objects, the doors and the visited cells lie,
        which the plain LSTM did not learn to keep.
      num_classes: Number of segmentation classes.
      num_actions: Number of discrete actions.
    """

    width: int = 120
    height: int = 90
    conv_channels: tuple[int, ...] = (64, 64, 128, 128)
    kernel: int = 5
    stride: int = 2
    hidden: int = 256
    lstm: int = 256
    seg_embed: int = 8
    max_depth: float = 10.0
    use_semantic: bool = False
    target_input: bool = False
    prev_action: bool = False
    aux: bool = False
    map_input: bool = False
    num_classes: int = rooms.NUM_SEG_CLASSES
    num_actions: int = rooms.NUM_ACTIONS

    def __post_init__(self):
        object.__setattr__(self, "conv_channels", tuple(self.conv_channels))
        _check_pixels(self)
        _check_positive_tuple("conv_channels", self.conv_channels)
        for name in ("kernel", "stride", "hidden", "lstm", "num_actions"):
            _check_positive(name, getattr(self, name))
        for name in ("use_semantic", "target_input", "prev_action", "aux", "map_input"):
            if not isinstance(getattr(self, name), bool):
                raise ValueError(f"{name} must be a bool, got {getattr(self, name)!r}")


@dataclasses.dataclass(frozen=True)
class RoomClassifierConfig:
    """Architecture of the multi-view room classifier (defaults: the paper's).

    Attributes:
      width: View width in pixels.
      height: View height in pixels.
      channels: Output channels of each 3x3 conv layer (each followed by
        BatchNorm and ReLU).
      strides: Stride of each conv layer; same length as ``channels``.
      kernel: Conv kernel size.
      mlp_hidden: Hidden units of the output MLP.
      num_views: Views per sample (4 panoramic views, or the last 4 frames
        for outdoor).
      seg_embed: Segmentation encoding, as in :class:`PolicyConfig`.
      max_depth: Depth clip and scale, as in :class:`PolicyConfig`.
      num_classes: Number of segmentation classes.
      num_room_types: Outputs: one sigmoid logit per room type.
    """

    width: int = 120
    height: int = 90
    channels: tuple[int, ...] = (4, 8, 16, 16, 32, 32, 64, 64, 128, 256)
    strides: tuple[int, ...] = (1, 1, 1, 2, 1, 2, 1, 2, 1, 2)
    kernel: int = 3
    mlp_hidden: int = 32
    num_views: int = 4
    seg_embed: int = 8
    max_depth: float = 10.0
    num_classes: int = rooms.NUM_SEG_CLASSES
    num_room_types: int = rooms.NUM_ROOM_TYPES

    def __post_init__(self):
        object.__setattr__(self, "channels", tuple(self.channels))
        object.__setattr__(self, "strides", tuple(self.strides))
        _check_pixels(self)
        _check_positive_tuple("channels", self.channels)
        _check_positive_tuple("strides", self.strides)
        if len(self.channels) != len(self.strides):
            raise ValueError(
                f"channels ({len(self.channels)} layers) and strides "
                f"({len(self.strides)} layers) must have the same length"
            )
        for name in ("kernel", "mlp_hidden", "num_views", "num_room_types"):
            _check_positive(name, getattr(self, name))


#: How a map-goal network reads its goal logits off the features (``GoalNetConfig.goal_head``).
GOAL_HEADS = ("linear", "conv")


@dataclasses.dataclass(frozen=True)
class GoalNetConfig:
    """Architecture of the map-goal network of the map-goal sub-policy.

    Attributes:
      width, height: Resolution of the frames its maps are built from (the
        map's detail depends on it, so a network is tied to it as the pixel
        policies are).
      channels: Output channels of each 3x3 stride-2 conv layer over the
        egocentric map.
      hidden: Units of the linear layer after the conv stack (the node's
        one-hot joins its output).
      map_channels: Channels of the map (``len(mapping.CHANNELS)``).
      window: Cells on each side of the egocentric map; the network scores
        each of its ``window ** 2`` cells as the next goal.
      num_nodes: Graph nodes it serves (one-hot input).
      context: Whether it also reads the coarse 16 m window around the agent
        (``EgoMapper.context``; its channels follow the fine window's).
      cues: Whether its maps mark the target's cues (``mapping.CUES``: fences
        and trees for ``outdoor``).
      semantic: Whether its maps mark every room type's see-objects in channels
        of their own (``mapping.SEMANTIC``, after the ``map_channels``).
      room_bits: Whether it also reads the observation's room-type bits (``rooms.NUM_ROOM_TYPES``
        values beside the node's one-hot): the semantic-augmented policy μ_s of the paper's baseline.
      potential: Whether it also predicts, for every cell of the window, how much farther (geodesic
        metres) the target lies from that cell than from the agent: a dense map of where the target
        is likely to be, trained by regression on the house's plan (session 14, docs/training.md).
      goals: What the sub-policy picks its goals from: ``logits`` (the goal logits' argmax; the
        potential head, if any, is then a training loss only) or ``potential`` (the walk down the
        predicted potential, ``goal_teacher.potential_goal``; needs ``potential``).
      decoder: How the potential head maps the features to the window's cells: ``linear`` (one
        Linear layer from the feature vector, as the goal logits) or ``conv`` (transposed convs back
        up the conv stack to half the window's size, each joined by that level's maps, as a U-Net,
        then upsampled: a dense map keeps its walls).
      goal_head: How the goal logits are read off the features: ``linear`` (one Linear layer from the
        feature vector to every cell: each cell's weights learned on their own) or ``conv`` (a U-Net
        decoder as ``decoder`` ``conv``'s, conditioned on the whole feature vector, then one 3x3 conv to a
        logit per cell: the same weights score every cell, so what makes a door a goal at one place of the
        window is learned for all of them; session 15).
    """

    width: int = 40
    height: int = 30
    channels: tuple[int, ...] = (32, 64, 64)
    hidden: int = 256
    map_channels: int = 6
    window: int = 32
    num_nodes: int = len(rooms.GRAPH_NODES)
    context: bool = False
    cues: bool = False
    semantic: bool = False
    room_bits: bool = False
    potential: bool = False
    decoder: str = "linear"
    goals: str = "logits"
    goal_head: str = "linear"

    @property
    def input_channels(self) -> int:
        """Channels of the maps it reads: the fine window's (with ``semantic`` one more per room type of
        ``mapping.SEMANTIC``), and with ``context`` the coarse window's."""
        fine = self.map_channels + (len(mapping.SEMANTIC) if self.semantic else 0)
        return fine * (2 if self.context else 1)

    def __post_init__(self):
        object.__setattr__(self, "channels", tuple(self.channels))
        _check_positive_tuple("channels", self.channels)
        for name in ("width", "height", "hidden", "map_channels", "window", "num_nodes"):
            _check_positive(name, getattr(self, name))
        for name in ("context", "cues", "semantic", "room_bits", "potential"):
            if not isinstance(getattr(self, name), bool):
                raise ValueError(f"{name} must be a bool, got {getattr(self, name)!r}")
        if self.decoder not in ("linear", "conv"):
            raise ValueError(f"decoder {self.decoder!r}: expected 'linear' or 'conv'")
        if self.goal_head not in GOAL_HEADS:
            raise ValueError(f"goal_head {self.goal_head!r}: expected 'linear' or 'conv'")
        if self.goals not in ("logits", "potential"):
            raise ValueError(f"goals {self.goals!r}: expected 'logits' or 'potential'")
        if self.goals == "potential" and not self.potential:
            raise ValueError("goals 'potential' are read off the potential head: expected potential True")
        if self.decoder == "conv" and not self.potential:
            raise ValueError("decoder 'conv' decodes the potential head: expected potential True")
        if self.window % 2 ** len(self.channels):
            raise ValueError(f"window {self.window} must be a multiple of 2 ** {len(self.channels)} "
                             f"(one halving per conv layer)")


@dataclasses.dataclass(frozen=True)
class ControllerConfig:
    """Architecture of the HRL baseline's LSTM controller.

    Attributes:
      num_room_types: K; the input is 4K floats and the output K sub-targets.
      lstm: LSTM units (50 in the original release).
    """

    num_room_types: int = rooms.NUM_ROOM_TYPES
    lstm: int = 50

    def __post_init__(self):
        _check_positive("num_room_types", self.num_room_types)
        _check_positive("lstm", self.lstm)
