"""The trainer skeleton: one resumable, kill-safe loop shared by every trainer.

A run lives in one folder. Every ``checkpoint_every`` iterations (and at the
end of each call to :meth:`Trainer.train`) the trainer writes its state
atomically (a temporary file moved into place), so a run killed at any
moment resumes from its last checkpoint, and a run longer than a session
proceeds in parts: call ``train`` again with the same configuration and
folder. Resuming under another configuration is refused, naming every
differing field. Every iteration logs one row to ``progress.csv`` (rows past
the last checkpoint are dropped on resume, so the CSV never holds an
iteration twice) and to TensorBoard, and advances a progress bar.

A trainer keeps only what is its own: :meth:`Trainer.iterate` (one
iteration: rollouts and an update, an epoch, a batch of houses),
:meth:`Trainer.state` / :meth:`Trainer.load_state` (what its checkpoint
holds besides the counters) and optionally :meth:`Trainer.session` (what
lives across iterations, e.g. worker processes) and :meth:`Trainer.publish`
(the files it ships, e.g. the policy). Trainers with a network set
``model`` and ``optimizer`` and the checkpoint is a
:func:`leaps_mj.learning.checkpoints.save_checkpoint` file; those without one (the
prior's exploration counts) write JSON.
"""

from __future__ import annotations

import argparse
import contextlib
import csv
import dataclasses
import io
import json
import os
import pathlib
import time
from typing import Any

import tqdm

from leaps_mj.world import files


def parse_bool(text: str) -> bool:
    """A command-line boolean: true / false (also 1 / 0, yes / no)."""
    if text.lower() in ("1", "true", "yes"):
        return True
    if text.lower() in ("0", "false", "no"):
        return False
    raise argparse.ArgumentTypeError(f"{text!r}: expected true or false")


def parse_ints(text: str) -> tuple[int, ...]:
    """A command-line tuple of integers: comma-separated."""
    try:
        return tuple(int(v) for v in text.split(","))
    except ValueError:
        raise argparse.ArgumentTypeError(f"{text!r}: expected comma-separated integers") from None


def add_config_arguments(parser: argparse.ArgumentParser, config_class, skip: tuple[str, ...] = ()) -> None:
    """One ``--field-name`` option per field of a trainer's config dataclass (default None: the preset's
    value), typed by the field's default: booleans as true / false, tuples as comma-separated integers."""
    group = parser.add_argument_group("configuration overrides (default: the preset's value)")
    for field in dataclasses.fields(config_class):
        if field.name in skip:
            continue
        default = field.default
        kind = {bool: parse_bool, tuple: parse_ints}.get(type(default), type(default))
        group.add_argument(f"--{field.name.replace('_', '-')}", dest=field.name, type=kind, default=None,
                           metavar=type(default).__name__.upper())


def config_overrides(args: argparse.Namespace, config_class, skip: tuple[str, ...] = ()) -> dict[str, Any]:
    """The config fields given on the command line (by :func:`add_config_arguments`)."""
    return {f.name: getattr(args, f.name) for f in dataclasses.fields(config_class)
            if f.name not in skip and getattr(args, f.name) is not None}


def plain(value: Any) -> Any:
    """``value`` as JSON values (tuples become lists), as a checkpoint stores it."""
    return json.loads(json.dumps(value))


def check_same_config(path, saved: dict, config, growable: frozenset[str] = frozenset()) -> None:
    """Refuses to resume a run under another configuration.

    A field the checkpoint lacks (added to the dataclass after it was
    written) counts as saved at its default, so runs checkpointed before a
    new option still resume.

    Args:
      path: the checkpoint being resumed (named in the error).
      saved: the configuration stored in it (a dict).
      config: the configuration dataclass given now.
      growable: fields that may be given larger than saved (a run extended).

    Raises:
      ValueError: naming every differing field with its saved and given value.
    """
    defaults = {f.name: f.default for f in dataclasses.fields(config) if f.default is not dataclasses.MISSING}
    saved, given = plain({**defaults, **saved}), plain(dataclasses.asdict(config))
    diff = {k: (saved.get(k), v) for k, v in given.items()
            if saved.get(k) != v and not (k in growable and v > saved.get(k))}
    if diff:
        fields = ", ".join(f"{k}: saved {a!r}, given {b!r}" for k, (a, b) in diff.items())
        raise ValueError(f"{path} holds a run with another configuration ({fields}); "
                         "rerun with the same options or another --out")


def _fmt(value: Any) -> Any:
    return f"{value:.6g}" if isinstance(value, float) else value


class CsvLog:
    """Rows appended to a CSV file; on opening, rows after the last checkpoint are dropped.

    Args:
      path: the CSV file.
      key: the column counting iterations.
      keep_through: keep existing rows whose ``key`` is at most this.
      fields: the columns; None takes those of the file, or else of the first row written.
    """

    def __init__(self, path: pathlib.Path, key: str, keep_through: int, fields: tuple[str, ...] | None = None):
        self.path, self.fields = path, tuple(fields) if fields else None
        rows = []
        if path.exists():
            with open(path, newline="") as f:
                reader = csv.DictReader(f)
                rows = [r for r in reader if int(r[key]) <= keep_through]
                self.fields = self.fields or (tuple(reader.fieldnames) if reader.fieldnames else None)
        if self.fields:
            self._rewrite(rows)
        elif path.exists():
            path.unlink()

    def _rewrite(self, rows: list[dict]) -> None:
        text = io.StringIO()
        writer = csv.DictWriter(text, self.fields, extrasaction="ignore")
        writer.writeheader()
        writer.writerows(rows)
        files.write_atomic(self.path, text.getvalue().encode())

    def write(self, row: dict[str, Any]) -> None:
        if self.fields is None:
            self.fields = tuple(row)
            self._rewrite([])
        with open(self.path, "a", newline="") as f:
            csv.writer(f).writerow([_fmt(row.get(k, "")) for k in self.fields])


class Trainer:
    """Base of the trainers: counters, checkpoints, resume, logs, progress bar.

    Class attributes a subclass may set:
      unit: name of the iteration counter in checkpoints and logs
        ("iteration", "epoch", "update", "house").
      csv_fields: fixed CSV columns, or None for those of the first row.
      loss_keys: logged keys that go to TensorBoard's "losses" group (others to "charts").
      growable: config fields a resumed run may be given larger than it was begun with, where the
        run then goes on exactly as if begun with the larger value (a run's total, where nothing is
        scheduled over it): a finished run is extended.

    Args:
      config: the run's configuration dataclass (stored and checked on resume).
      out: the folder of checkpoints and logs.
      total: iterations of the whole run.
      checkpoint_every: write the checkpoint every this many iterations.
      state_name: file name of the checkpoint in ``out``.
      progress: show a progress bar.
      desc: the progress bar's label.
    """

    unit = "iteration"
    csv_fields: tuple[str, ...] | None = None
    loss_keys: frozenset[str] = frozenset()
    growable: frozenset[str] = frozenset()
    #: Set by trainers with a network (before :meth:`resume`).
    model = None
    optimizer = None

    def __init__(self, config, out: str | os.PathLike, total: int, checkpoint_every: int = 1,
                 state_name: str = "state.pt", progress: bool = True, desc: str = "train"):
        if isinstance(checkpoint_every, bool) or not isinstance(checkpoint_every, int) or checkpoint_every < 1:
            raise ValueError(f"checkpoint_every {checkpoint_every!r}: expected a positive integer")
        self.config = config
        self.out = pathlib.Path(out)
        self.total = total
        self.checkpoint_every = checkpoint_every
        self.state_path = self.out / state_name
        self.progress = progress
        self.desc = desc
        self.iteration = 0
        self.elapsed = 0.0
        #: The TensorBoard writer while :meth:`train` runs (for scalars logged inside an iteration).
        self.writer = None

    # -- what a trainer defines ---------------------------------------------------------------
    def iterate(self) -> dict[str, Any]:
        """Runs one iteration; returns the row to log (without the counter)."""
        raise NotImplementedError

    def state(self) -> dict[str, Any]:
        """What the checkpoint holds besides the counters, the config and the network (plain values)."""
        return {}

    def load_state(self, extra: dict[str, Any]) -> None:
        """Restores :meth:`state` from a checkpoint's contents."""

    def session(self) -> contextlib.AbstractContextManager:
        """A context open for the iterations of one :meth:`train` call (environments, workers)."""
        return contextlib.nullcontext()

    def publish(self, extra: dict[str, Any]) -> None:
        """Writes the run's shipped files at a checkpoint (e.g. the policy file)."""

    def postfix(self, row: dict[str, Any]) -> dict[str, str]:
        """What the progress bar shows after an iteration."""
        return {}

    # -- checkpoints ----------------------------------------------------------------------
    @property
    def finished(self) -> bool:
        return self.iteration >= self.total

    def extra(self) -> dict[str, Any]:
        """The checkpoint's metadata: counters, config and the trainer's own state."""
        return {self.unit: self.iteration, "elapsed": self.elapsed,
                "train_config": plain(dataclasses.asdict(self.config)), **self.state()}

    def resume(self, expect_width: int | None = None, expect_height: int | None = None) -> bool:
        """Loads the checkpoint if there is one (refusing another configuration); returns whether it did."""
        if not self.state_path.exists():
            return False
        if self.model is not None:
            from leaps_mj.learning import checkpoints

            model, _, extra = checkpoints.load_policy(self.state_path, expect_width, expect_height)
            check_same_config(self.state_path, extra["train_config"], self.config, self.growable)
            self.model.load_state_dict(model.state_dict())
            if self.optimizer is not None:
                self.optimizer.load_state_dict(extra["optimizer"])
        else:
            try:
                extra = json.loads(self.state_path.read_text())
            except json.JSONDecodeError as e:
                raise ValueError(f"checkpoint {self.state_path} is not valid JSON: {e}") from None
            check_same_config(self.state_path, extra["train_config"], self.config, self.growable)
        self.iteration, self.elapsed = extra[self.unit], extra.get("elapsed", 0.0)
        self.load_state(extra)
        return True

    def save(self) -> None:
        """Writes the checkpoint (atomically), then the shipped files."""
        extra = self.extra()
        if self.model is not None:
            from leaps_mj.learning import checkpoints

            state = {**extra, "optimizer": self.optimizer.state_dict()} if self.optimizer is not None else extra
            device = next(self.model.parameters()).device
            model = self.model.to("cpu")
            checkpoints.save_checkpoint(self.state_path, model, model.config, state)
            self.model.to(device)
        else:
            files.write_atomic(self.state_path, (json.dumps(extra) + "\n").encode())
        self.publish(extra)

    # -- the loop -----------------------------------------------------------------------------
    def hyperparameters(self) -> dict[str, Any]:
        """The table shown in TensorBoard's text tab at the start of a run."""
        return dataclasses.asdict(self.config)

    def log_step(self, row: dict[str, Any]) -> int:
        """The TensorBoard step of a logged row (default: the iteration)."""
        return self.iteration

    def train(self, stop_after: int | None = None) -> None:
        """Runs iterations until the run is complete, or ``stop_after`` more are done.

        Checkpoints every ``checkpoint_every`` iterations and after the last
        one of this call.
        """
        from torch.utils.tensorboard import SummaryWriter

        if self.finished:
            return
        stop = self.total if stop_after is None else min(self.total, self.iteration + stop_after)
        self.out.mkdir(parents=True, exist_ok=True)
        writer = self.writer = SummaryWriter(str(self.out))
        if self.iteration == 0:
            rows = "\n".join(f"|{k}|{v}|" for k, v in self.hyperparameters().items())
            writer.add_text("hyperparameters", f"|param|value|\n|-|-|\n{rows}")
        log = CsvLog(self.out / "progress.csv", self.unit, self.iteration, self.csv_fields)
        bar = tqdm.tqdm(total=self.total, initial=self.iteration, desc=self.desc, unit=self.unit,
                        disable=not self.progress, dynamic_ncols=True)
        try:
            with self.session():
                while self.iteration < stop:
                    t0 = time.perf_counter()
                    scalars = self.iterate()
                    self.iteration += 1
                    self.elapsed += time.perf_counter() - t0
                    row = {self.unit: self.iteration, **scalars}
                    step = self.log_step(row)
                    for key, value in scalars.items():
                        if isinstance(value, (int, float)) and not isinstance(value, bool):
                            group = "losses" if key in self.loss_keys else "charts"
                            writer.add_scalar(f"{group}/{key}", value, step)
                    log.write(row)
                    bar.update(1)
                    bar.set_postfix(self.postfix(row), refresh=False)
                    if self.iteration % self.checkpoint_every == 0 or self.iteration == stop:
                        self.save()
        finally:
            bar.close()
            writer.close()
