"""Trains the CNN room-type classifier on balanced panoramas from the training houses.

``python -m leaps_mj.train classifier --preset tiny|cpu|paper --out DIR``

Data. For every room type k the generator draws ``per_type`` positive and
as many negative samples: a house (one with a room of type k for a
positive), a uniformly drawn free cell inside (or outside) the rooms of type k
and a uniform heading. From there the agent takes ``walk_steps`` uniformly
random actions; the sample is the pose it ends at, kept only if its
ground-truth bit k there is what was asked for (redrawn otherwise). The
input is the :func:`leaps_mj.learning.classifier.panorama` at that pose, or for
outdoor samples the last 4 frames of the walk; the label is all 8
ground-truth bits. The training houses give the training set, the valid
split's houses the validation set (made once, cached in ``DIR``).

Loss. Binary cross-entropy per room type, where it applies: the 7 indoor
types on panorama samples, outdoor on last-frames samples, each weighted so
its positives and negatives count equally. Adam, random horizontal flips of
all 4 views together (a mirrored house is still a house).

Model selection. After every epoch the per-type accuracy (threshold 0.5) on
the validation samples asked for that type (half positive) is measured; the
checkpoint with the best mean is ``DIR/classifier.pt``. Also reported at the
test-time confidence 0.85: the share of positives reaching it (TPR) and of
negatives reaching it (FPR).

Files under ``DIR``: ``classifier.pt`` (best), ``state.pt`` (resumable
state after the last epoch), ``data_train.npz`` / ``data_valid.npz``,
``progress.csv`` (one row per epoch), ``metrics.json`` (the best epoch's
validation metrics), ``samples.png`` (a validation sample per room type),
TensorBoard events. Re-running the same command resumes;
a different configuration is refused.
"""

from __future__ import annotations

import argparse
import contextlib
import dataclasses
import io
import json
import os
import pathlib
import sys
import time
from typing import Sequence

import numpy as np
import torch
import torch.nn.functional as F
import tqdm

from leaps_mj.environment import roomnav
from leaps_mj.environment.roomnav import EpisodeSpec
from leaps_mj.learning import checkpoints, classifier, nets
from leaps_mj.learning import trainer as trainer_lib
from leaps_mj.world import dataset as dataset_lib
from leaps_mj.world import files
from leaps_mj.world import houses, rooms

K = rooms.NUM_ROOM_TYPES
#: Tries at drawing a pose whose final bit is the one asked for, before giving up on that house.
MAX_TRIES = 50


@dataclasses.dataclass(frozen=True)
class TrainConfig:
    """A classifier training run (one per preset).

    Attributes:
      dataset: House dataset name or folder (train split for training, valid for selection).
      width, height: View resolution of the data and the network.
      channels, strides, kernel, mlp_hidden, seg_embed: Network
        (:class:`leaps_mj.learning.nets.RoomClassifierConfig`; defaults: the paper's CNN).
      train_per_type: Positive (and as many negative) training samples per room type.
      valid_per_type: The same for the validation samples.
      walk_steps: Random actions before a sample (>= 3 gives 4 distinct last frames).
      epochs: Passes over the training samples.
      batch_size: Samples per update.
      lr: Adam learning rate.
      weight_decay: Adam weight decay.
      seed: Seed of the data draws, the initialisation and the shuffling.
    """

    dataset: str = dataset_lib.CANONICAL
    width: int = 40
    height: int = 30
    channels: tuple[int, ...] = (4, 8, 16, 16, 32, 32, 64, 64, 128, 256)
    strides: tuple[int, ...] = (1, 1, 1, 2, 1, 2, 1, 2, 1, 2)
    kernel: int = 3
    mlp_hidden: int = 32
    seg_embed: int = 8
    train_per_type: int = 200
    valid_per_type: int = 100
    walk_steps: int = 3
    epochs: int = 12
    batch_size: int = 64
    lr: float = 1e-3
    weight_decay: float = 1e-5
    seed: int = 0

    def __post_init__(self):
        for name in ("train_per_type", "valid_per_type", "walk_steps", "epochs", "batch_size"):
            value = getattr(self, name)
            if isinstance(value, bool) or not isinstance(value, int) or value < 1:
                raise ValueError(f"{name} {value!r}: expected a positive integer")
        if self.batch_size < 2:
            raise ValueError(f"batch_size {self.batch_size}: expected at least 2 (BatchNorm)")
        if not self.lr > 0 or not self.weight_decay >= 0:
            raise ValueError(f"lr {self.lr!r} / weight_decay {self.weight_decay!r}: expected > 0 / >= 0")
        self.model_config()  # validates the network fields

    def model_config(self) -> nets.RoomClassifierConfig:
        return nets.RoomClassifierConfig(width=self.width, height=self.height, channels=self.channels,
                                         strides=self.strides, kernel=self.kernel, mlp_hidden=self.mlp_hidden,
                                         seg_embed=self.seg_embed)


PRESETS = {
    # Seconds: tests and smoke runs (small net, a handful of samples).
    "tiny": TrainConfig(width=24, height=18, channels=(4, 8, 16), strides=(1, 2, 2), mlp_hidden=8,
                        train_per_type=3, valid_per_type=2, epochs=2, batch_size=8),
    # About 10-15 minutes on 2 shared CPU cores: the paper's CNN at 40x30.
    "cpu": TrainConfig(),
    # The paper's resolution and more data (a GPU or a long CPU run).
    "paper": TrainConfig(width=120, height=90, train_per_type=2000, valid_per_type=500, epochs=30),
}


# -- data ------------------------------------------------------------------------------------------


def _draw_pose(hm, room_type: str, positive: bool, rng: np.random.Generator) -> tuple[float, float, float]:
    """A uniform free cell inside (positive) or outside the rooms of ``room_type``, and a uniform heading."""
    grid = hm.grid
    inside = grid.room_mask(room_type)
    mask = inside if positive else grid.free & ~inside & (grid.room_id >= 0)
    cells = np.flatnonzero(mask.ravel())
    ij = np.unravel_index(cells[rng.integers(cells.size)], mask.shape)
    x, y = grid.to_world(ij)
    return float(x), float(y), float(rng.uniform(-np.pi, np.pi))


def _walk(env, spec: EpisodeSpec, steps: int, rng: np.random.Generator):
    """Starts at ``spec`` and takes random actions; returns the last time step and last 4 frames."""
    ts = env.reset_to(spec)
    frames = [ts]
    for _ in range(steps):
        if ts.last():
            break
        ts = env.step(int(rng.integers(rooms.NUM_ACTIONS)))
        frames.append(ts)
    frames = ([frames[0]] * classifier.NUM_VIEWS + frames)[-classifier.NUM_VIEWS:]
    seg = np.stack([f.observation["segmentation"] for f in frames])
    depth = np.stack([f.observation["depth"] for f in frames])
    return ts, seg, depth


def make_samples(config: TrainConfig, split: str, per_type: int, seed: int, progress: bool = True) -> dict:
    """Balanced samples of one split (see the module docstring).

    Returns:
      ``{"seg": (S, 4, H, W) uint8, "depth": (S, 4, H, W) float16, "bits": (S, K) uint8,
      "query": (S,) int64 room type asked for, "positive": (S,) bool}``; room
      types no house of the split has are left out.
    """
    house_types = {p.stem: [t for t in rooms.ROOM_TYPES if t in houses.House.load(p).room_types]
                   for p in dataset_lib.list_houses(config.dataset, split)}
    ids = sorted(house_types)
    rng = np.random.default_rng(seed)
    plan = []
    for k, room_type in enumerate(rooms.ROOM_TYPES):
        having = [h for h in ids if room_type in house_types[h]]
        if not having:
            print(f"classifier data ({split}): no house has a {room_type}; no samples of it", file=sys.stderr)
            continue
        for positive in (True, False):
            pool = having if positive else ids
            plan += [(pool[int(rng.integers(len(pool)))], k, positive) for _ in range(per_type)]
    plan.sort(key=lambda item: item[0])  # house by house: each house compiled once
    env = roomnav.load(config.dataset, split, seed=seed, width=config.width, height=config.height,
                        horizon=config.walk_steps, reward="sparse", cache_size=2)
    out = {"seg": [], "depth": [], "bits": [], "query": [], "positive": []}
    try:
        for house, k, positive in tqdm.tqdm(plan, desc=f"classifier data ({split})", disable=not progress):
            hm = env.house_model(house)
            room_type = rooms.ROOM_TYPES[k]
            for _ in range(MAX_TRIES):
                spec = EpisodeSpec(house, _draw_pose(hm, room_type, positive, rng), house_types[house][0])
                ts, seg, depth = _walk(env, spec, config.walk_steps, rng)
                bits = ts.observation["semantic"]
                if bool(bits[k]) == positive:
                    break
            else:
                raise RuntimeError(f"house {house!r}: no {'positive' if positive else 'negative'} {room_type} "
                                   f"pose in {MAX_TRIES} tries")
            if k != classifier.OUTDOOR:
                seg, depth = classifier.panorama(env)
            out["seg"].append(seg)
            out["depth"].append(depth.astype(np.float16))
            out["bits"].append(bits)
            out["query"].append(k)
            out["positive"].append(positive)
    finally:
        env.close()
    return {"seg": np.stack(out["seg"]).astype(np.uint8), "depth": np.stack(out["depth"]),
            "bits": np.stack(out["bits"]).astype(np.uint8), "query": np.array(out["query"], dtype=np.int64),
            "positive": np.array(out["positive"], dtype=bool)}


def loss_mask(query: np.ndarray) -> np.ndarray:
    """(S, K) float: 1 where a sample's label trains that output (outdoor: last frames; others: panoramas)."""
    outdoor = (np.asarray(query) == classifier.OUTDOOR)[:, None]
    column = (np.arange(K) == classifier.OUTDOOR)[None, :]
    return (outdoor == column).astype(np.float32)


def pos_weight(bits: np.ndarray, mask: np.ndarray) -> np.ndarray:
    """Per-output weight of positives making them count as much as the negatives (1 where undefined)."""
    pos = (bits * mask).sum(0)
    neg = ((1 - bits) * mask).sum(0)
    return np.where((pos > 0) & (neg > 0), neg / np.maximum(pos, 1), 1.0).astype(np.float32)


def metrics(logits: np.ndarray, data: dict, threshold: float = classifier.CONFIDENCE) -> dict:
    """Per-type validation metrics on the samples asked for that type.

    Returns:
      ``{"accuracy": mean over types, "types": {type: {"n", "accuracy", "tpr", "fpr"}}}`` where
      accuracy thresholds the probability at 0.5 and tpr/fpr at ``threshold``.
    """
    per = {}
    for k in sorted(set(data["query"].tolist())):
        rows = data["query"] == k
        label = data["bits"][rows, k].astype(bool)
        p = 1.0 / (1.0 + np.exp(-logits[rows, k]))
        per[rooms.ROOM_TYPES[k]] = {
            "n": int(rows.sum()), "accuracy": float(np.mean((p >= 0.5) == label)),
            "tpr": float(np.mean(p[label] >= threshold)) if label.any() else float("nan"),
            "fpr": float(np.mean(p[~label] >= threshold)) if (~label).any() else float("nan"),
        }
    return {"accuracy": float(np.mean([m["accuracy"] for m in per.values()])), "types": per}


# -- training --------------------------------------------------------------------------------------


def _save_npz(path: pathlib.Path, arrays: dict) -> None:
    buf = io.BytesIO()
    np.savez_compressed(buf, **arrays)
    files.write_atomic(path, buf.getvalue())


class Trainer(trainer_lib.Trainer):
    """Trains (or resumes) a classifier run in ``out``; see the module docstring."""

    unit = "epoch"

    def __init__(self, config: TrainConfig, out: str | os.PathLike, progress: bool = True):
        super().__init__(config, out, config.epochs, progress=progress, desc="classifier epochs")
        self.best_path = self.out / "classifier.pt"
        torch.manual_seed(config.seed)
        self.model = nets.RoomClassifier(config.model_config())
        self.optimizer = torch.optim.Adam(self.model.parameters(), lr=config.lr, weight_decay=config.weight_decay)
        self.best: dict | None = None
        self.history: list[dict] = []
        self.resume()

    @property
    def epoch(self) -> int:
        return self.iteration

    def state(self) -> dict:
        return {"best": self.best, "history": self.history}

    def load_state(self, extra: dict) -> None:
        self.best, self.history = extra["best"], extra["history"]

    def publish(self, extra: dict) -> None:
        files.write_atomic(self.out / "metrics.json", (json.dumps(self.best, indent=1) + "\n").encode())

    def data(self, split: str) -> dict:
        """The samples of a split, made once and cached in ``out``."""
        path = self.out / f"data_{split}.npz"
        if not path.exists():
            per_type = self.config.train_per_type if split == "train" else self.config.valid_per_type
            seed = int(np.random.SeedSequence([self.config.seed, 1 if split == "train" else 2]).generate_state(1)[0])
            self.out.mkdir(parents=True, exist_ok=True)
            _save_npz(path, make_samples(self.config, split, per_type, seed, self.progress))
        with np.load(path) as f:
            return {k: f[k] for k in f.files}

    def _logits(self, data: dict) -> np.ndarray:
        self.model.eval()
        try:
            return np.concatenate([classifier.RoomTypeClassifier(self.model).logits(
                data["seg"][i:i + 256], data["depth"][i:i + 256].astype(np.float32))
                for i in range(0, len(data["query"]), 256)])
        finally:
            self.model.train()

    def train(self, stop_after: int | None = None) -> dict:
        """Runs the remaining epochs (or ``stop_after`` more); returns the best validation metrics so far."""
        super().train(stop_after)
        return self.best

    @contextlib.contextmanager
    def session(self):
        """The training and validation samples, the loss mask and class weights of one ``train`` call."""
        self._train, self._valid = self.data("train"), self.data("valid")
        self._mask = loss_mask(self._train["query"])
        self._weight = torch.as_tensor(pos_weight(self._train["bits"], self._mask))
        self.model.train()
        yield

    def iterate(self) -> dict:
        c, train, mask = self.config, self._train, self._mask
        t0 = time.perf_counter()
        n = len(train["query"])
        step = self.epoch * ((n + c.batch_size - 1) // c.batch_size)
        rng = np.random.default_rng([c.seed, self.epoch])
        order = rng.permutation(n)
        losses = []
        for i in tqdm.trange(0, n, c.batch_size, desc=f"classifier epoch {self.epoch + 1}/{c.epochs}",
                             disable=not self.progress, leave=False):
            rows = np.sort(order[i:i + c.batch_size])
            if rows.size < 2:
                continue
            seg, depth = train["seg"][rows], train["depth"][rows].astype(np.float32)
            flip = rng.random(rows.size) < 0.5
            seg[flip], depth[flip] = seg[flip][..., ::-1], depth[flip][..., ::-1]
            x = nets.ActorCritic.preprocess({"segmentation": seg, "depth": depth})
            logits = self.model(x["segmentation"], x["depth"])
            target = torch.as_tensor(train["bits"][rows], dtype=torch.float32)
            m = torch.as_tensor(mask[rows])
            loss = (F.binary_cross_entropy_with_logits(logits, target, pos_weight=self._weight, reduction="none")
                    * m).sum() / m.sum()
            self.optimizer.zero_grad()
            loss.backward()
            self.optimizer.step()
            losses.append(loss.item())
            self.writer.add_scalar("losses/bce", loss.item(), step)
            step += 1
        epoch = self.epoch + 1
        result = metrics(self._logits(self._valid), self._valid)
        row = {"train_loss": float(np.mean(losses)), "valid_accuracy": result["accuracy"],
               "seconds": time.perf_counter() - t0,
               **{f"valid_{t}": m["accuracy"] for t, m in result["types"].items()}}
        self.history.append({"epoch": epoch, **row})
        if self.best is None or result["accuracy"] > self.best["accuracy"]:
            self.best = {**result, "epoch": epoch}
            checkpoints.save_checkpoint(self.best_path, self.model, self.model.config,
                                 {**self.extra(), "epoch": epoch})
        print(f"epoch {epoch}: train loss {row['train_loss']:.3f}, valid accuracy "
              f"{result['accuracy']:.3f} (best {self.best['accuracy']:.3f} at epoch {self.best['epoch']})",
              flush=True)
        return row


def format_metrics(best: dict) -> str:
    """The best epoch's per-type validation metrics as a markdown table."""
    lines = [f"validation (best epoch {best['epoch']}): mean accuracy {best['accuracy']:.3f}", "",
             "| room type | samples | accuracy (p >= 0.5) | TPR (p >= 0.85) | FPR (p >= 0.85) |",
             "|---|---|---|---|---|"]
    for t, m in best["types"].items():
        lines.append(f"| {t} | {m['n']} | {m['accuracy']:.3f} | {m['tpr']:.3f} | {m['fpr']:.3f} |")
    return "\n".join(lines)


def plot_samples(data: dict, path: str | os.PathLike) -> None:
    """The first positive sample of each room type: its 4 views (segmentation colours) and its bits."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    from leaps_mj.records import recorder as record
    from leaps_mj.world import topdown

    kinds = [k for k in range(K) if np.any((data["query"] == k) & data["positive"])]
    fig, axes = plt.subplots(len(kinds), classifier.NUM_VIEWS, figsize=(7.2, 1.45 * len(kinds)), squeeze=False)
    for row, k in zip(axes, kinds):
        i = int(np.flatnonzero((data["query"] == k) & data["positive"])[0])
        for v, ax in enumerate(row):
            ax.imshow(record.colorize(data["seg"][i, v]), interpolation="nearest")
            ax.set_xticks([])
            ax.set_yticks([])
        source = "last 4 frames" if k == classifier.OUTDOOR else "panorama 0/90/180/270°"
        on = [rooms.ROOM_TYPES[j] for j in np.flatnonzero(data["bits"][i])]
        row[0].set_ylabel(rooms.ROOM_TYPES[k], fontsize=8)
        row[-1].yaxis.set_label_position("right")
        row[-1].set_ylabel(f"{source}\nbits: {', '.join(on)}", fontsize=6, rotation=0, ha="left", va="center")
    fig.suptitle("Room classifier samples (validation houses), one positive per type", fontsize=9)
    fig.tight_layout()
    topdown.save_figure(fig, path)


# -- command line ------------------------------------------------------------------------------------


def build_parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(prog="python -m leaps_mj.train classifier", description=__doc__.split("\n\n")[0],
                                     formatter_class=argparse.ArgumentDefaultsHelpFormatter)
    parser.add_argument("--preset", choices=sorted(PRESETS), default="cpu", help="base configuration")
    parser.add_argument("--out", default="runs/classifier", help="output folder (resumed if it holds a run)")
    parser.add_argument("--threads", type=int, default=1, help="torch CPU threads")
    parser.add_argument("--stop-after", type=int, default=None,
                        help="stop after this many more epochs (checkpointed; rerun resumes)")
    parser.add_argument("--no-progress", action="store_true", help="no progress bars")
    trainer_lib.add_config_arguments(parser, TrainConfig)
    return parser


def main(argv: Sequence[str] | None = None) -> int:
    args = build_parser().parse_args(argv)
    for name in ("threads", "stop_after"):
        if getattr(args, name) is not None and getattr(args, name) < 1:
            raise ValueError(f"--{name.replace('_', '-')} {getattr(args, name)}: expected a positive integer")
    config = dataclasses.replace(PRESETS[args.preset], **trainer_lib.config_overrides(args, TrainConfig))
    torch.set_num_threads(args.threads)
    trainer = Trainer(config, args.out, progress=not args.no_progress)
    best = trainer.train(args.stop_after)
    if not trainer.finished:
        print(f"stopped after epoch {trainer.epoch} of {config.epochs}; rerun the same command to resume")
    print(f"{trainer.model.num_parameters():,} parameters; best checkpoint {trainer.best_path}")
    print(format_metrics(best))
    plot_samples(trainer.data("valid"), trainer.out / "samples.png")
    print(f"wrote {trainer.out / 'samples.png'}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
