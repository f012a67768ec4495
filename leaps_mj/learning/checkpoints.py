"""Checkpoints of the networks in :mod:`leaps_mj.learning.nets`, written atomically, checked on load.

:func:`save_checkpoint` / :func:`load_policy` store a network with its config,
the segmentation class table and the resolution, so a policy trained at one
resolution or with another class table is refused at load time rather than
producing silent garbage.
"""

import dataclasses
import io
import os
import pathlib
from typing import Any, Mapping

import torch

from leaps_mj.learning.net_configs import ControllerConfig, GoalNetConfig, PolicyConfig, RoomClassifierConfig
from leaps_mj.learning.nets import ActorCritic, ControllerNet, GoalNet, RoomClassifier
from leaps_mj.world import files, rooms

#: Tag stored in every checkpoint, checked on load.
CHECKPOINT_FORMAT = "leaps_mj.nets/1"

_NETS = {
    "PolicyConfig": (PolicyConfig, ActorCritic),
    "GoalNetConfig": (GoalNetConfig, GoalNet),
    "RoomClassifierConfig": (RoomClassifierConfig, RoomClassifier),
    "ControllerConfig": (ControllerConfig, ControllerNet),
}

_PLAIN = (type(None), bool, int, float, str, torch.Tensor)


def _check_plain(value: Any, where: str) -> None:
    """Checks ``value`` holds only what ``torch.load(weights_only=True)`` reads back."""
    if isinstance(value, dict):
        for key, item in value.items():
            if not isinstance(key, (str, int)):
                raise ValueError(f"{where} has key {key!r} of type {type(key).__name__}; use str or int keys")
            _check_plain(item, f"{where}[{key!r}]")
    elif isinstance(value, (list, tuple)):
        for i, item in enumerate(value):
            _check_plain(item, f"{where}[{i}]")
    elif not isinstance(value, _PLAIN):
        raise ValueError(
            f"{where} is a {type(value).__name__}; checkpoints hold only None, bool, int, float, "
            "str, tensors, lists, tuples and dicts (convert numpy values with .tolist() or torch.as_tensor)"
        )


def _resolution(config: Any) -> tuple[int, int] | None:
    return (config.width, config.height) if hasattr(config, "width") else None


def save_checkpoint(
    path: str | os.PathLike, model: torch.nn.Module, config: Any, extra: Mapping[str, Any] | None = None
) -> None:
    """Writes ``model`` with its config, the class table and resolution, atomically.

    The file is written to a temporary file in the same directory, synced and
    moved into place (:func:`leaps_mj.world.files.write_atomic`), so a crash
    never leaves a half-written checkpoint under ``path``. Parent directories are created.

    Args:
      path: Destination file.
      model: An :class:`~leaps_mj.learning.nets.ActorCritic`, ``RoomClassifier``, ``ControllerNet`` or ``GoalNet``.
      config: The model's config (must equal ``model.config``).
      extra: Training metadata (step, target room, metrics...) made of plain
        Python values and tensors.

    Raises:
      ValueError: if ``config`` is not the model's, or ``extra`` holds other types.
    """
    name = type(config).__name__
    if name not in _NETS or not isinstance(model, _NETS[name][1]):
        raise ValueError(f"cannot save a {type(model).__name__} with a {name}")
    if config != model.config:
        raise ValueError(f"config {config} differs from the model's {model.config}")
    extra = dict(extra or {})
    _check_plain(extra, "extra")
    payload = {
        "format": CHECKPOINT_FORMAT,
        "config_class": name,
        "config": dataclasses.asdict(config),
        "seg_classes": list(rooms.SEG_CLASSES),
        "resolution": _resolution(config),
        "state_dict": {k: v.detach().cpu() for k, v in model.state_dict().items()},
        "extra": extra,
    }
    buffer = io.BytesIO()
    torch.save(payload, buffer)
    files.write_atomic(path, buffer.getvalue(), fsync=True)


def load_policy(
    path: str | os.PathLike,
    expect_width: int | None = None,
    expect_height: int | None = None,
) -> tuple[torch.nn.Module, Any, dict]:
    """Loads a checkpoint written by :func:`save_checkpoint`.

    Works for any of the four networks; the model comes back on the CPU in
    eval mode (call ``.train()`` to resume training).

    Args:
      path: Checkpoint file.
      expect_width: If given, the width the model must have been built for
        (ignored for the controller, which takes no pixels).
      expect_height: If given, the height the model must have been built for.

    Returns:
      (model, config, extra).

    Raises:
      ValueError: naming the file, if it is missing, unreadable or not a
        leaps_mj checkpoint, if its class table differs from
        ``rooms.SEG_CLASSES``, or if its resolution differs from the expected one.
    """
    path = pathlib.Path(path)
    if not path.is_file():
        raise ValueError(f"checkpoint {path} does not exist")
    try:
        payload = torch.load(path, map_location="cpu", weights_only=True)
    except Exception as err:  # torch raises many types for a damaged file.
        raise ValueError(
            f"checkpoint {path} is corrupt or not a torch file ({type(err).__name__}; see the chained error)"
        ) from err
    if not isinstance(payload, dict) or payload.get("format") != CHECKPOINT_FORMAT:
        raise ValueError(f"{path} is not a {CHECKPOINT_FORMAT} checkpoint")
    if payload["config_class"] not in _NETS:
        raise ValueError(f"checkpoint {path} holds an unknown config class {payload['config_class']!r}")
    config_class, net_class = _NETS[payload["config_class"]]
    if tuple(payload["seg_classes"]) != rooms.SEG_CLASSES:
        raise ValueError(
            f"checkpoint {path} was trained with segmentation classes {payload['seg_classes']}, "
            f"but this code has {list(rooms.SEG_CLASSES)}"
        )
    resolution = payload["resolution"]
    if resolution is not None:
        width, height = resolution
        want = (
            width if expect_width is None else expect_width,
            height if expect_height is None else expect_height,
        )
        if (width, height) != want:
            raise ValueError(
                f"checkpoint {path} was trained at {width}x{height} (width x height) "
                f"but {want[0]}x{want[1]} was expected"
            )
    try:
        config = config_class(**payload["config"])
        model = net_class(config)
        model.load_state_dict(payload["state_dict"])
    except (TypeError, RuntimeError) as err:
        raise ValueError(f"checkpoint {path} does not match the {net_class.__name__} code: {err}") from err
    model.eval()
    return model, config, payload["extra"]
