"""Neural networks of LEAPS and its baselines.

Four networks, each built from a frozen config dataclass (defined in
:mod:`leaps_mj.learning.net_configs`, importable from here):

* :class:`ActorCritic` — the sub-policy μ(θ) of the paper: a CNN over the
  segmentation + depth frame, a linear layer, an LSTM and policy / value
  heads, trained with A2C/A3C on ``t_max``-step unrolls. With
  ``PolicyConfig(use_semantic=True)`` it is the semantic-augmented policy μ_s,
  which also sees the room-type bits and the target one-hot. With
  ``target_input=True`` one network serves every graph node (it reads the
  node's one-hot, ``node``); with ``aux=True`` it has auxiliary heads that
  only training reads (:meth:`ActorCritic.aux_outputs`); with
  ``map_input=True`` it also reads the agent's egocentric map (``egomap``).
* :class:`RoomClassifier` — predicts the K room-type bits from 4 views with a
  shared per-view CNN and a learned attention over the views.
* :class:`ControllerNet` — the LSTM controller of the HRL baseline, choosing
  the next sub-target room type from semantic bits.
* :class:`GoalNet` — the map-goal sub-policy's network: scores every cell of
  the agent's egocentric map as the place to walk to next.

Observations follow the environment's keys, batched: ``segmentation`` int
(B, H, W) class ids in ``[0, NUM_SEG_CLASSES)``, ``depth`` float (B, H, W) in
metres, ``semantic`` (B, K) room-type bits, ``target`` (B, K) one-hot and
``node`` (B, K + 1) one-hot of the graph node a shared sub-policy heads for
and ``egomap`` uint8 (B, C, S, S) the egocentric map of
:mod:`leaps_mj.environment.mapping`.
:meth:`ActorCritic.preprocess` turns the numpy observations into tensors.

Checkpoints of these networks are written and read by
:mod:`leaps_mj.learning.checkpoints`.
"""

import math
from typing import Any, Mapping

import numpy as np
import torch
import torch.nn.functional as F
from torch import nn

from leaps_mj.environment import mapping
from leaps_mj.learning.net_configs import (GOAL_HEADS, ControllerConfig, GoalNetConfig, PolicyConfig,
                                           RoomClassifierConfig)
from leaps_mj.world import rooms

#: (h, c) of an LSTM, each (B, units).
State = tuple[torch.Tensor, torch.Tensor]

#: Vertical strips of the frame in the auxiliary room-view label (left to right).
VIEW_COLUMNS = 5
#: Metres per unit of the auxiliary distance head (distances are clipped at 2 units).
AUX_DISTANCE_SCALE = 5.0
#: Output channels of the egocentric map's conv layers (3x3, stride 2) and units of its linear layer.
MAP_CHANNELS = (16, 32, 32)
MAP_HIDDEN = 128


def _layer_init(layer: nn.Module, std: float = math.sqrt(2.0)) -> nn.Module:
    """Orthogonal weights and zero bias, the usual actor-critic initialisation."""
    nn.init.orthogonal_(layer.weight, std)
    if layer.bias is not None:
        nn.init.zeros_(layer.bias)
    return layer


def _lstm_cell(inputs: int, units: int) -> nn.LSTMCell:
    cell = nn.LSTMCell(inputs, units)
    for name, param in cell.named_parameters():
        if "weight" in name:
            nn.init.orthogonal_(param, 1.0)
        else:
            nn.init.zeros_(param)
    return cell


def _reset(state: State, done: torch.Tensor | None) -> State:
    """Zeroes the state rows whose ``done`` is 1 (an episode began there)."""
    if done is None:
        return state
    keep = (1.0 - done.to(state[0].dtype)).unsqueeze(-1)
    return state[0] * keep, state[1] * keep


class _Net(nn.Module):
    """Base of the networks here; each also has a ``config`` attribute."""

    def num_parameters(self) -> int:
        """Number of trainable parameters."""
        return sum(p.numel() for p in self.parameters() if p.requires_grad)


class _PixelInput(nn.Module):
    """Turns segmentation ids + depth into conv input planes (N, C, H, W).

    Segmentation becomes ``seg_embed`` learned planes (or one-hot planes when
    ``seg_embed`` is 0); depth becomes one plane clipped and scaled to [0, 1].
    """

    def __init__(self, num_classes: int, seg_embed: int, max_depth: float):
        super().__init__()
        self.num_classes = num_classes
        self.max_depth = max_depth
        self.embed = nn.Embedding(num_classes, seg_embed) if seg_embed else None
        self.channels = (seg_embed or num_classes) + 1

    def forward(self, seg: torch.Tensor, depth: torch.Tensor) -> torch.Tensor:
        seg = seg.long()
        if self.embed is None:
            planes = F.one_hot(seg, self.num_classes).float()
        else:
            planes = self.embed(seg)
        depth = depth.float().clamp(0.0, self.max_depth) / self.max_depth
        return torch.cat([planes.permute(0, 3, 1, 2), depth.unsqueeze(1)], dim=1)


def _check_frames(name: str, tensor: torch.Tensor, width: int, height: int, lead: int) -> None:
    """Checks that ``tensor`` is ``lead`` leading dims followed by (height, width)."""
    if tensor.dim() != lead + 2 or tuple(tensor.shape[-2:]) != (height, width):
        raise ValueError(
            f"{name} has shape {tuple(tensor.shape)}; expected {lead} leading dim(s) then "
            f"(height, width) = ({height}, {width}) for a net built for {width}x{height}"
        )


def _check_leading(name: str, tensor: torch.Tensor, lead: tuple[int, ...]) -> None:
    """Checks that a per-step scalar input has exactly the frames' leading dims."""
    if tuple(tensor.shape) != lead:
        raise ValueError(f"{name} has shape {tuple(tensor.shape)}; expected {lead}")


def _require_keys(obs: Mapping[str, Any], keys: tuple[str, ...]) -> None:
    missing = [k for k in keys if k not in obs]
    if missing:
        raise ValueError(f"observation lacks {missing}; it has {sorted(obs)}")


class ActorCritic(_Net):
    """CNN + LSTM actor-critic over segmentation + depth (the sub-policy μ(θ)).

    conv stack -> Linear(hidden) -> ReLU -> [+ semantic bits, target one-hot
    when ``use_semantic``] [+ node one-hot when ``target_input``] [+ map
    features when ``map_input``] -> LSTMCell(lstm) -> [+ node one-hot when
    ``target_input``] [+ map features when ``map_input``] -> policy logits
    and value. The map features (3 stride-2 3x3 convs and a linear layer over
    the egocentric map) also bypass the LSTM, so the heads read the map of
    this step directly.

    The LSTM runs step by step (an ``LSTMCell``) so that :meth:`forward` and
    :meth:`forward_sequence` compute the same function and episode boundaries
    inside an unroll reset the state exactly where they occur.
    """

    def __init__(self, config: PolicyConfig):
        super().__init__()
        self.config = config
        self.pixels = _PixelInput(config.num_classes, config.seg_embed, config.max_depth)
        layers = []
        in_channels = self.pixels.channels
        for channels in config.conv_channels:
            layers += [
                _layer_init(nn.Conv2d(in_channels, channels, config.kernel, config.stride, config.kernel // 2)),
                nn.ReLU(),
            ]
            in_channels = channels
        self.conv = nn.Sequential(*layers, nn.Flatten())
        with torch.no_grad():
            dummy = torch.zeros(1, self.pixels.channels, config.height, config.width)
            flat = self.conv(dummy).shape[1]
        self.fc = nn.Sequential(_layer_init(nn.Linear(flat, config.hidden)), nn.ReLU())
        nodes = len(rooms.GRAPH_NODES) if config.target_input else 0
        skip = MAP_HIDDEN if config.map_input else 0
        if config.map_input:
            layers, in_channels = [], len(mapping.CHANNELS)
            for channels in MAP_CHANNELS:
                layers += [_layer_init(nn.Conv2d(in_channels, channels, 3, 2, 1)), nn.ReLU()]
                in_channels = channels
            side = mapping.WINDOW // 2 ** len(MAP_CHANNELS)
            self.map_net = nn.Sequential(*layers, nn.Flatten(),
                                         _layer_init(nn.Linear(in_channels * side * side, MAP_HIDDEN)), nn.ReLU())
        lstm_in = (config.hidden + (2 * rooms.NUM_ROOM_TYPES if config.use_semantic else 0) + nodes
                   + (config.num_actions if config.prev_action else 0) + skip)
        self.lstm = _lstm_cell(lstm_in, config.lstm)
        self.policy = _layer_init(nn.Linear(config.lstm + nodes + skip, config.num_actions), std=0.01)
        self.value = _layer_init(nn.Linear(config.lstm + nodes + skip, 1), std=1.0)
        if config.aux:
            self.aux_view = _layer_init(nn.Linear(config.hidden, len(rooms.GRAPH_NODES) * VIEW_COLUMNS), std=0.01)
            self.aux_here = _layer_init(nn.Linear(config.lstm + nodes + skip, rooms.NUM_ROOM_TYPES), std=0.01)
            self.aux_distance = _layer_init(nn.Linear(config.lstm + nodes + skip, 1), std=0.01)

    def input_keys(self) -> tuple[str, ...]:
        """Observation keys the network reads."""
        cfg = self.config
        return (("segmentation", "depth") + (("semantic", "target") if cfg.use_semantic else ())
                + (("node",) if cfg.target_input else ()) + (("prev_action",) if cfg.prev_action else ())
                + (("egomap",) if cfg.map_input else ()))

    @staticmethod
    def preprocess(
        obs: Mapping[str, np.ndarray], device: torch.device | str | None = None
    ) -> dict[str, torch.Tensor]:
        """Converts numpy observations to tensors of the dtypes the net takes.

        Shapes are kept, so both (B, ...) and (T, B, ...) batches work. Keys
        other than ``segmentation``, ``depth``, ``semantic``, ``target``,
        ``node``, ``prev_action`` and ``egomap`` are dropped.

        Raises:
          ValueError: if a segmentation id is outside ``[0, NUM_SEG_CLASSES)``.
        """
        out = {}
        if "segmentation" in obs:
            seg = np.asarray(obs["segmentation"])
            if seg.size and (seg.min() < 0 or seg.max() >= rooms.NUM_SEG_CLASSES):
                raise ValueError(
                    f"segmentation ids span [{seg.min()}, {seg.max()}]; "
                    f"expected [0, {rooms.NUM_SEG_CLASSES})"
                )
            out["segmentation"] = torch.as_tensor(seg, dtype=torch.long, device=device)
        if "prev_action" in obs:
            out["prev_action"] = torch.as_tensor(np.asarray(obs["prev_action"]), dtype=torch.long, device=device)
        for key in ("depth", "semantic", "target", "node", "egomap"):
            if key in obs:
                out[key] = torch.as_tensor(np.asarray(obs[key]), dtype=torch.float32, device=device)
        return out

    def initial_state(self, batch: int, device: torch.device | str | None = None) -> State:
        """Zero LSTM state (h, c), each (batch, lstm)."""
        zeros = torch.zeros(batch, self.config.lstm, device=device)
        return zeros, zeros.clone()

    def _features(self, obs: Mapping[str, torch.Tensor],
                  lead: int) -> tuple[torch.Tensor, torch.Tensor, torch.Tensor | None]:
        """Frame features (N, hidden), LSTM inputs (N, F) and the map features that bypass the LSTM
        (N, MAP_HIDDEN; None without ``map_input``) for observations with ``lead`` leading dims."""
        cfg = self.config
        _require_keys(obs, self.input_keys())
        seg, depth = obs["segmentation"], obs["depth"]
        _check_frames("segmentation", seg, cfg.width, cfg.height, lead)
        _check_frames("depth", depth, cfg.width, cfg.height, lead)
        frame = self.fc(self.conv(self.pixels(seg.reshape(-1, cfg.height, cfg.width),
                                               depth.reshape(-1, cfg.height, cfg.width))))
        extra, skip = [], None
        for key in self.input_keys()[2:]:
            if key == "egomap":
                shape = (len(mapping.CHANNELS), mapping.WINDOW, mapping.WINDOW)
                expected = tuple(seg.shape[:lead]) + shape
                if tuple(obs[key].shape) != expected:
                    raise ValueError(f"egomap has shape {tuple(obs[key].shape)}; expected {expected}")
                skip = self.map_net(obs[key].float().reshape(-1, *shape))
                extra.append(skip)
                continue
            if key == "prev_action":
                _check_leading(key, obs[key], tuple(seg.shape[:lead]))
                onehot = F.one_hot(obs[key].long().reshape(-1) + 1, cfg.num_actions + 1)[:, 1:]
                extra.append(onehot.float())
                continue
            width = len(rooms.GRAPH_NODES) if key == "node" else rooms.NUM_ROOM_TYPES
            expected = tuple(seg.shape[:lead]) + (width,)
            if tuple(obs[key].shape) != expected:
                raise ValueError(f"{key} has shape {tuple(obs[key].shape)}; expected {expected}")
            extra.append(obs[key].float().reshape(frame.shape[0], -1))
        return frame, torch.cat([frame, *extra], dim=1) if extra else frame, skip

    def _head_input(self, h: torch.Tensor, obs: Mapping[str, torch.Tensor],
                    skip: torch.Tensor | None) -> torch.Tensor:
        """The LSTM output, with the node one-hot when the network is shared by the nodes and the
        map features when it reads the map."""
        parts = [h]
        if self.config.target_input:
            parts.append(obs["node"].float().reshape(*h.shape[:-1], -1))
        if skip is not None:
            parts.append(skip.reshape(*h.shape[:-1], -1))
        return torch.cat(parts, dim=-1) if len(parts) > 1 else h

    def _heads(self, h: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor]:
        return self.policy(h), self.value(h).squeeze(-1)

    def forward(
        self,
        obs: Mapping[str, torch.Tensor],
        state: State,
        done_mask: torch.Tensor | None = None,
    ) -> tuple[torch.Tensor, torch.Tensor, State]:
        """One time step.

        Args:
          obs: Tensors with a leading batch dim (B, ...).
          state: (h, c) from :meth:`initial_state` or the previous step.
          done_mask: Optional (B,) float; 1 where an episode began at this
            step, whose state rows are zeroed before the step.

        Returns:
          logits (B, num_actions), value (B,), new state.
        """
        _, x, skip = self._features(obs, lead=1)
        h, c = self.lstm(x, _reset(state, done_mask))
        logits, value = self._heads(self._head_input(h, obs, skip))
        return logits, value, (h, c)

    def forward_sequence(
        self,
        obs: Mapping[str, torch.Tensor],
        state: State,
        dones: torch.Tensor,
    ) -> tuple[torch.Tensor, torch.Tensor, State]:
        """An unroll of T steps (e.g. A2C's ``t_max`` = 30).

        The CNN runs on all T*B frames at once; the LSTM steps through time,
        resetting rows where ``dones[t]`` is 1 before step t — the same result
        as calling :meth:`forward` T times.

        Args:
          obs: Tensors with leading (T, B) dims.
          state: (h, c) at the start of the unroll.
          dones: (T, B) float; 1 where an episode began at that step.

        Returns:
          logits (T, B, num_actions), values (T, B), state after the last step.
        """
        out = self.unroll(obs, state, dones)
        return out["logits"], out["values"], out["state"]

    def unroll(self, obs: Mapping[str, torch.Tensor], state: State, dones: torch.Tensor) -> dict[str, Any]:
        """:meth:`forward_sequence` with what the auxiliary heads read.

        Returns:
          ``logits``, ``values`` and ``state`` as :meth:`forward_sequence`,
          ``frame`` (T, B, hidden) frame features and ``head`` (T, B, F) the
          heads' input (LSTM outputs, with the node one-hot when shared).
        """
        frame, x, skip = self._features(obs, lead=2)
        steps, batch = obs["segmentation"].shape[:2]
        if tuple(dones.shape) != (steps, batch):
            raise ValueError(f"dones has shape {tuple(dones.shape)}; expected (T, B) = ({steps}, {batch})")
        x = x.reshape(steps, batch, -1)
        hs = []
        for t in range(steps):
            state = self.lstm(x[t], _reset(state, dones[t]))
            hs.append(state[0])
        head = self._head_input(torch.stack(hs), obs, skip)
        logits, values = self._heads(head)
        return {"logits": logits, "values": values, "state": state, "frame": frame.reshape(steps, batch, -1),
                "head": head}

    def aux_outputs(self, out: dict[str, Any]) -> dict[str, torch.Tensor]:
        """The auxiliary heads' outputs for an :meth:`unroll` (``aux=True`` only).

        Returns:
          ``view`` (T, B, K + 1, VIEW_COLUMNS) logits of "this strip shows a
          room of node k", ``here`` (T, B, K) logits of the room-type bits and
          ``distance`` (T, B) the predicted geodesic distance (in units of
          :data:`AUX_DISTANCE_SCALE` metres).

        Raises:
          ValueError: if the network has no auxiliary heads.
        """
        if not self.config.aux:
            raise ValueError("this network has no auxiliary heads (PolicyConfig.aux is False)")
        steps, batch = out["head"].shape[:2]
        view = self.aux_view(out["frame"]).reshape(steps, batch, len(rooms.GRAPH_NODES), VIEW_COLUMNS)
        return {"view": view, "here": self.aux_here(out["head"]),
                "distance": self.aux_distance(out["head"]).squeeze(-1)}


class RoomClassifier(_Net):
    """Predicts the room-type bits from several views with attention over views.

    Each view goes through the same CNN (3x3 conv + BatchNorm + ReLU per
    layer, then global average pooling). A linear layer scores each view's
    feature, a softmax over views turns scores into weights, and the weighted
    sum of features feeds an MLP giving one sigmoid logit per room type.
    Global pooling makes the net work at any view resolution.
    """

    def __init__(self, config: RoomClassifierConfig):
        super().__init__()
        self.config = config
        self.pixels = _PixelInput(config.num_classes, config.seg_embed, config.max_depth)
        layers = []
        in_channels = self.pixels.channels
        for channels, stride in zip(config.channels, config.strides):
            layers += [
                nn.Conv2d(in_channels, channels, config.kernel, stride, config.kernel // 2, bias=False),
                nn.BatchNorm2d(channels),
                nn.ReLU(),
            ]
            in_channels = channels
        self.cnn = nn.Sequential(*layers, nn.AdaptiveAvgPool2d(1), nn.Flatten())
        self.score = nn.Linear(in_channels, 1)
        self.mlp = nn.Sequential(
            nn.Linear(in_channels, config.mlp_hidden),
            nn.ReLU(),
            nn.Linear(config.mlp_hidden, config.num_room_types),
        )

    def attend(self, seg: torch.Tensor, depth: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor]:
        """Attention-pooled feature (B, C) and the view weights (B, num_views)."""
        cfg = self.config
        for name, tensor in (("seg", seg), ("depth", depth)):
            if tensor.dim() != 4 or tensor.shape[1] != cfg.num_views:
                raise ValueError(
                    f"{name} has shape {tuple(tensor.shape)}; expected (B, {cfg.num_views}, H, W)"
                )
        batch, views, height, width = seg.shape
        if tuple(depth.shape) != tuple(seg.shape):
            raise ValueError(f"depth shape {tuple(depth.shape)} differs from seg shape {tuple(seg.shape)}")
        x = self.pixels(seg.reshape(-1, height, width), depth.reshape(-1, height, width))
        features = self.cnn(x).reshape(batch, views, -1)
        weights = torch.softmax(self.score(features).squeeze(-1), dim=1)
        return (weights.unsqueeze(-1) * features).sum(dim=1), weights

    def forward(self, seg: torch.Tensor, depth: torch.Tensor) -> torch.Tensor:
        """Room-type logits (B, num_room_types) from seg (B, V, H, W) ids and depth (B, V, H, W) metres."""
        pooled, _ = self.attend(seg, depth)
        return self.mlp(pooled)


class ControllerNet(_Net):
    """LSTM controller of the HRL baseline: picks the next sub-target room type.

    Input per step (4K floats): current room-type bits, OR-accumulated bits
    since the episode began, target one-hot, last sub-target one-hot. Output:
    logits over the K sub-targets and a value. With K = 8 and 50 units it has
    17,259 parameters, against the 38 of the semantic model (36 edge
    probabilities of the 9-node graph plus 2 observation-noise rates).
    """

    def __init__(self, config: ControllerConfig = ControllerConfig()):
        super().__init__()
        self.config = config
        self.lstm = _lstm_cell(4 * config.num_room_types, config.lstm)
        self.policy = _layer_init(nn.Linear(config.lstm, config.num_room_types), std=0.01)
        self.value = _layer_init(nn.Linear(config.lstm, 1), std=1.0)

    def initial_state(self, batch: int, device: torch.device | str | None = None) -> State:
        """Zero LSTM state (h, c), each (batch, lstm)."""
        zeros = torch.zeros(batch, self.config.lstm, device=device)
        return zeros, zeros.clone()

    def forward(
        self, x: torch.Tensor, state: State, done_mask: torch.Tensor | None = None
    ) -> tuple[torch.Tensor, torch.Tensor, State]:
        """One option step: x (B, 4K) -> logits (B, K), value (B,), new state.

        ``done_mask`` (B,) zeroes the state rows where an episode began.
        """
        expected = 4 * self.config.num_room_types
        if x.dim() != 2 or x.shape[1] != expected:
            raise ValueError(f"controller input has shape {tuple(x.shape)}; expected (B, {expected})")
        h, c = self.lstm(x.float(), _reset(state, done_mask))
        return self.policy(h), self.value(h).squeeze(-1), (h, c)


#: Config class name -> (config class, network class), for loading.
class GoalNet(_Net):
    """Scores the cells of the egocentric map as the next goal (the map-goal sub-policy).

    3x3 stride-2 convs over the map -> Linear(hidden) -> ReLU -> [+ node
    one-hot, + room-type bits with ``room_bits``] -> Linear(window ** 2): one
    logit per map cell, trained with cross-entropy on the cell the geodesic
    path leads to (:mod:`leaps_mj.learning.train_goal`). With ``potential`` a
    second Linear(window ** 2) on the same features predicts each cell's
    geodesic metres to the target relative to the agent's (:meth:`heads`). With ``goal_head``
    ``conv`` the goal logits come instead from a U-Net decoder conditioned on the feature vector, one
    3x3 conv scoring every cell alike. One network serves every graph node; the map's ``target``
    channel already holds the node's objects.
    """

    def __init__(self, config: GoalNetConfig = GoalNetConfig()):
        super().__init__()
        self.config = config
        layers, in_channels = [], config.input_channels
        for channels in config.channels:
            layers += [_layer_init(nn.Conv2d(in_channels, channels, 3, 2, 1)), nn.ReLU()]
            in_channels = channels
        side = config.window // 2 ** len(config.channels)
        self.conv = nn.Sequential(*layers, nn.Flatten(),
                                  _layer_init(nn.Linear(in_channels * side * side, config.hidden)), nn.ReLU())
        bits = rooms.NUM_ROOM_TYPES if config.room_bits else 0
        features = config.hidden + config.num_nodes + bits
        self.out, self.goal_up = None, None
        if config.goal_head == "linear":
            self.out = _layer_init(nn.Linear(features, config.window ** 2), std=0.01)
        else:
            self.goal_up, width = self._decoder(features)
            self.out = _layer_init(nn.Conv2d(width, 1, 3, 1, 1), std=0.01)
        self.potential = _layer_init(nn.Linear(features, config.window ** 2), std=0.01) \
            if config.potential and config.decoder == "linear" else None
        self.up = None
        if config.potential and config.decoder == "conv":
            self.up, width = self._decoder(config.num_nodes + bits)
            self.potential = _layer_init(nn.Conv2d(width, 1, 3, 1, 1), std=0.01)

    def _decoder(self, condition: int) -> tuple[nn.ModuleList, int]:
        """A U-Net decoder from the deepest maps (+ ``condition`` features as planes) up to half the window,
        each level joined by the encoder's maps of its size (full size costs this machine 3x the learner's
        time; the heads upsample), and the channels it ends with."""
        channels = self.config.channels
        widths = [16 * 2 ** k for k in reversed(range(len(channels) - 1))]
        layers, in_channels = [], channels[-1] + condition
        for width, skip in zip(widths, reversed(channels[:-1])):
            layers.append(_layer_init(nn.ConvTranspose2d(in_channels, width, 4, 2, 1)))
            in_channels = width + skip
        return nn.ModuleList(layers), in_channels

    @staticmethod
    def _decode(up: nn.ModuleList, head: nn.Module, levels: list[torch.Tensor], condition: torch.Tensor,
                size) -> torch.Tensor:
        """One value per window cell (B, window ** 2): the decoder ``up`` from the encoder's ``levels``
        (input first) with ``condition`` (B, C) as planes at the deepest, ``head``, then upsampled to ``size``."""
        deepest = levels[-1]
        x = torch.cat([deepest, condition[:, :, None, None].expand(-1, -1, *deepest.shape[-2:])], dim=1)
        for layer, skip in zip(up, reversed(levels[1:-1])):
            x = torch.cat([F.relu(layer(x)), skip], dim=1)
        return F.interpolate(head(x), size=size, mode="bilinear", align_corners=False).flatten(1)

    def forward(self, egomap: torch.Tensor, node: torch.Tensor, bits: torch.Tensor | None = None) -> torch.Tensor:
        """Goal logits (B, window ** 2), row-major over the window, from maps (B, C, window, window)
        (any numeric dtype; cells are 0/1), node indices (B,) ints and, with ``room_bits``, the
        room-type bits (B, NUM_ROOM_TYPES).

        Raises:
          ValueError: as :meth:`heads`.
        """
        return self.heads(egomap, node, bits)[0]

    def heads(self, egomap: torch.Tensor, node: torch.Tensor,
              bits: torch.Tensor | None = None) -> tuple[torch.Tensor, torch.Tensor | None]:
        """The goal logits (B, window ** 2) and, with ``potential``, each cell's predicted geodesic metres
        to the target minus the agent's (B, window ** 2; None without), from the inputs of :meth:`forward`.

        Raises:
          ValueError: for maps, node indices or bits of another shape or range; for bits given to a
            network without ``room_bits`` or missing for one with it.
        """
        cfg = self.config
        shape = (cfg.input_channels, cfg.window, cfg.window)
        if egomap.dim() != 4 or tuple(egomap.shape[1:]) != shape:
            raise ValueError(f"egomap has shape {tuple(egomap.shape)}; expected (B, {shape[0]}, {shape[1]}, {shape[2]})")
        if tuple(node.shape) != egomap.shape[:1] or (node.numel() and not 0 <= int(node.min()) <= int(node.max())
                                                     < cfg.num_nodes):
            raise ValueError(f"node has shape {tuple(node.shape)} and values {node.tolist()[:8]}; expected "
                             f"({egomap.shape[0]},) indices in [0, {cfg.num_nodes})")
        x = egomap.float()
        levels = [x]  # the input and each conv layer's maps, for the conv decoder
        for module in self.conv:
            x = module(x)
            if isinstance(module, nn.ReLU) and x.dim() == 4:
                levels.append(x)
        inputs = [x, F.one_hot(node.long(), cfg.num_nodes).float()]
        if cfg.room_bits != (bits is not None):
            raise ValueError(f"room-type bits {'missing' if bits is None else 'given'}: this network "
                             f"{'reads' if cfg.room_bits else 'does not read'} them (room_bits={cfg.room_bits})")
        if bits is not None:
            if tuple(bits.shape) != (egomap.shape[0], rooms.NUM_ROOM_TYPES):
                raise ValueError(f"bits has shape {tuple(bits.shape)}; expected ({egomap.shape[0]}, "
                                 f"{rooms.NUM_ROOM_TYPES})")
            inputs.append(bits.float())
        features = torch.cat(inputs, dim=1)
        size = egomap.shape[-2:]
        if self.goal_up is None:
            logits = self.out(features)
        else:
            logits = self._decode(self.goal_up, self.out, levels, features, size)
        if self.up is not None:
            potential = self._decode(self.up, self.potential, levels, features[:, cfg.hidden:], size)
        else:
            potential = self.potential(features) if self.potential is not None else None
        return logits, potential
