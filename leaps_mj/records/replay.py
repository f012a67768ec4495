"""Replays episode records (:mod:`leaps_mj.records.recorder`): summary, pictures, video, recovery.

Usage::

    python -m leaps_mj.replay FILE.mcap                      # episode summary
    python -m leaps_mj.replay FILE.mcap --topdown traj.png   # trajectory by sub-target
    python -m leaps_mj.replay FILE.mcap --video ep.mp4       # or --gif ep.gif
    python -m leaps_mj.replay FILE.mcap --preview view.png   # top-down + first-person frames
    python -m leaps_mj.replay RUN.mcap.part --recover ok.mcap   # salvage a killed run's file

The house is rebuilt from the JSON attached to the record, so replay needs no
dataset. A file that is not MCAP, is truncated (no footer: a run killed
mid-episode), is corrupt (a chunk fails its CRC) or is not an episode record
raises a ValueError saying which, and the CLI prints it and exits with
status 2.
"""

from __future__ import annotations

import argparse
import dataclasses
import importlib.util
import json
import os
import pathlib
import struct
import sys
from collections.abc import Sequence

import imageio.v2 as imageio
import matplotlib

matplotlib.use("Agg")
import matplotlib.collections as mcollections  # noqa: E402
import matplotlib.patches  # noqa: E402
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402
from mcap.decoder import DecoderFactory  # noqa: E402
from mcap.exceptions import McapError  # noqa: E402
from mcap.reader import make_reader  # noqa: E402
from mcap.stream_reader import StreamReader  # noqa: E402
from mcap.writer import Writer  # noqa: E402
from mcap_protobuf.decoder import DecoderFactory as ProtobufDecoderFactory  # noqa: E402
from PIL import Image, ImageDraw, ImageFont  # noqa: E402

from leaps_mj.records import recorder as record
from leaps_mj.world import files, houses, rooms, topdown  # noqa: E402

_MAGIC = b"\x89MCAP0\r\n"
#: Topics a record must have to be replayed (``/outcome`` is missing from a recovered file).
REQUIRED_TOPICS = (record.SEGMENTATION, record.DEPTH, record.POSE, record.SEMANTIC, record.EPISODE)
#: Line colour of the trajectory per sub-target room type (saturated: the floors use the pastel ROOM_COLORS).
SUBTARGET_COLORS = {node: matplotlib.colormaps["tab10"](i)[:3] for i, node in enumerate(rooms.GRAPH_NODES)}
_NO_SUBTARGET_COLOR = (0.1, 0.1, 0.1)
_UPSCALE = 3


class _JsonDecoderFactory(DecoderFactory):
    def decoder_for(self, message_encoding, schema):
        return json.loads if message_encoding == "json" else None


@dataclasses.dataclass(frozen=True)
class EpisodeRecord:
    """A decoded episode record.

    Attributes:
      path: the file.
      episode: the ``/episode`` message (spec, agent, index, run config).
      outcome: the ``/outcome`` message, or ``{"complete": False}`` for a recovered file.
      house: the house, rebuilt from the attached JSON.
      poses: (T + 1, 3) x, y, yaw per frame.
      segmentation: (T + 1, H, W) uint8 class ids per frame.
      depth: (T + 1, H, W) float32 metres per frame.
      steps: the ``/step`` messages (actions 1..T).
      subtargets: (T + 1) sub-target in force at each frame (None if the agent reports none).
    """

    path: pathlib.Path
    episode: dict
    outcome: dict
    house: houses.House
    poses: np.ndarray
    segmentation: np.ndarray
    depth: np.ndarray
    steps: list[dict]
    subtargets: list[str | None]

    @property
    def num_steps(self) -> int:
        return len(self.poses) - 1

    @property
    def target(self) -> str:
        return self.episode["spec"]["target"]


def _check_container(path: pathlib.Path) -> None:
    """ValueError unless ``path`` is a complete MCAP file (magic at both ends)."""
    if not path.is_file():
        raise ValueError(f"{str(path)!r} does not exist or is not a file")
    size = path.stat().st_size
    with open(path, "rb") as f:
        head = f.read(len(_MAGIC))
        f.seek(max(0, size - len(_MAGIC)))
        tail = f.read(len(_MAGIC))
    if head != _MAGIC:
        raise ValueError(f"{str(path)!r} is not an MCAP file (it does not start with the MCAP magic bytes)")
    if size < 2 * len(_MAGIC) or tail != _MAGIC:
        n = _count_salvageable(path)
        raise ValueError(f"{str(path)!r} is truncated (no MCAP footer: the writing run was killed or the copy "
                         f"is incomplete); {n} messages in complete chunks can be salvaged with "
                         f"`python -m leaps_mj.replay {path} --recover OUT.mcap`")


def _iter_complete_records(path: pathlib.Path):
    """Records of a possibly truncated MCAP file, stopping at the first incomplete one."""
    with open(path, "rb") as f:
        reader = StreamReader(f, validate_crcs=True)
        try:
            yield from reader.records
        except (McapError, struct.error, EOFError, ValueError):
            return


def _count_salvageable(path: pathlib.Path) -> int:
    from mcap.records import Message

    return sum(isinstance(r, Message) for r in _iter_complete_records(path))


def load(path: str | os.PathLike) -> EpisodeRecord:
    """Reads and decodes an episode record.

    Raises:
      ValueError: if the file is missing, not MCAP, truncated, corrupt, or
        lacks the channels or attachments of an episode record.
    """
    path = pathlib.Path(path)
    _check_container(path)
    by_topic: dict[str, list] = {}
    try:
        with open(path, "rb") as f:
            reader = make_reader(f, validate_crcs=True,
                                 decoder_factories=[ProtobufDecoderFactory(), _JsonDecoderFactory()])
            summary = reader.get_summary()
            topics = {c.topic for c in summary.channels.values()} if summary else set()
            if all(t in topics for t in REQUIRED_TOPICS):
                for _, channel, _, msg in reader.iter_decoded_messages():
                    by_topic.setdefault(channel.topic, []).append(msg)
            attachments = {a.name: a.data for a in reader.iter_attachments()}
    except Exception as e:  # noqa: BLE001 - damaged bytes surface as CRC, zstd, protobuf, JSON or struct errors
        raise ValueError(f"{str(path)!r} is a corrupt MCAP file ({type(e).__name__}: {e})") from None
    missing = [t for t in REQUIRED_TOPICS if t not in topics]
    if missing:
        raise ValueError(f"{str(path)!r} is MCAP but not a leaps_mj episode record: it lacks the channels "
                         f"{missing} (has {sorted(topics)})")
    episode = by_topic[record.EPISODE][0]
    house_id = episode["spec"]["house"]
    house_json = attachments.get(f"{house_id}.json")
    if house_json is None:
        raise ValueError(f"{str(path)!r} lacks the attachment '{house_id}.json' (the house description)")
    try:
        house = houses.House.from_json(json.loads(house_json), source=f"{path}:{house_id}.json")
    except json.JSONDecodeError as e:
        raise ValueError(f"{str(path)!r}: the attachment '{house_id}.json' is not valid JSON ({e}): a corrupt "
                         "file") from None
    poses = np.array([[m.pose.position.x, m.pose.position.y,
                       2 * np.arctan2(m.pose.orientation.z, m.pose.orientation.w)] for m in by_topic[record.POSE]])
    segmentation = np.stack([record.decolorize(_image(m, np.uint8, 3)) for m in by_topic[record.SEGMENTATION]])
    depth = np.stack([_image(m, np.float32, 1) for m in by_topic[record.DEPTH]])
    n = min(len(poses), len(segmentation), len(depth))
    complete = record.OUTCOME in by_topic
    if complete and not len(poses) == len(segmentation) == len(depth):
        raise ValueError(f"{str(path)!r}: {len(poses)} poses, {len(segmentation)} segmentation and {len(depth)} "
                         "depth frames; expected one of each per frame")
    # A recovered file ends mid-frame: keep the frames that are whole.
    subtargets: list[str | None] = [None] * n
    for m in by_topic.get(record.BELIEF, []):
        subtargets[m["step"]:] = [m["subtarget"]] * max(0, n - m["step"])
    outcome = by_topic[record.OUTCOME][0] if complete else {"complete": False}
    return EpisodeRecord(path, episode, outcome, house, poses[:n], segmentation[:n], depth[:n],
                         by_topic.get(record.STEP, [])[:n - 1], subtargets)


def _image(msg, dtype, channels: int) -> np.ndarray:
    shape = (msg.height, msg.width, channels) if channels > 1 else (msg.height, msg.width)
    return np.frombuffer(msg.data, dtype=dtype).reshape(shape)


def summary(rec: EpisodeRecord) -> str:
    """Human-readable summary: house, agent, target, outcome, sub-targets."""
    spec = rec.episode["spec"]
    types = sorted({r.type for r in rec.house.indoor_rooms})
    x, y, yaw = spec["start"]
    out = rec.outcome
    if out.get("complete", True):
        result = (f"{'success' if out['success'] else 'failure'} after {out['steps']} steps "
                  f"(return {out['return']:.2f})")
    else:
        result = f"incomplete record (recovered), {rec.num_steps} steps"
    geo = f"{spec['geodesic']:.1f} m" if spec.get("geodesic") is not None else "?"
    subs = out.get("subtargets") or [s for i, s in enumerate(rec.subtargets)
                                     if s is not None and (i == 0 or rec.subtargets[i - 1] != s)]
    lines = [
        f"record       {rec.path} ({rec.path.stat().st_size / 1024:.0f} KiB)",
        f"house        {rec.house.id}: {len(rec.house.indoor_rooms)} indoor rooms ({', '.join(types)})",
        f"agent        {rec.episode['agent']}",
        f"target       {spec['target']} from ({x:.2f}, {y:.2f}, {np.degrees(yaw):.0f} deg); geodesic {geo}, "
        f"plan length {spec.get('plan_length')}",
        f"outcome      {result}",
        f"sub-targets  {' -> '.join(subs) if subs else '(none reported)'}",
    ]
    return "\n".join(lines)


# -- pictures ---------------------------------------------------------------------

def _segments_by_subtarget(rec: EpisodeRecord):
    """Trajectory segments (frame k-1 -> k) and their colours (sub-target at frame k)."""
    xy = rec.poses[:, :2]
    segs = np.stack([xy[:-1], xy[1:]], axis=1)
    colors = [SUBTARGET_COLORS.get(s, _NO_SUBTARGET_COLOR) for s in rec.subtargets[1:]]
    return segs, colors


def draw_trajectory(ax, rec: EpisodeRecord, upto: int | None = None) -> list:
    """Draws the house and the trajectory (frames 0..upto) coloured by sub-target.

    Returns:
      Legend handles (sub-targets, start, agent) for the caller to place.
    """
    topdown.draw_house(ax, rec.house, furniture_labels=False)
    segs, colors = _segments_by_subtarget(rec)
    n = rec.num_steps if upto is None else upto
    ax.add_collection(mcollections.LineCollection(segs[:n], colors=colors[:n], linewidths=2.2, zorder=5))
    x0, y0, _ = rec.poses[0]
    x1, y1, yaw = rec.poses[n]
    ax.plot([x0], [y0], marker="o", ms=7, color="white", mec="black", zorder=6, label="start")
    ax.plot([x1], [y1], marker="o", ms=7, color="black", zorder=6, label="agent")
    ax.arrow(x1, y1, 0.5 * np.cos(yaw), 0.5 * np.sin(yaw), width=0.05, color="black", zorder=6)
    used = [s for s in dict.fromkeys(rec.subtargets[1:n + 1]) if s is not None]
    handles = [matplotlib.lines.Line2D([], [], color=SUBTARGET_COLORS[s], lw=2.2, label=f"sub-target: {s}")
               for s in used]
    return handles + ax.get_legend_handles_labels()[0]


def _title(rec: EpisodeRecord) -> str:
    out = rec.outcome
    status = ("success" if out.get("success") else "failure") if out.get("complete", True) else "incomplete"
    return f"{rec.episode['agent']} in {rec.house.id}: target {rec.target}, {status} in {rec.num_steps} steps"


def save_topdown(rec: EpisodeRecord, path: str | os.PathLike) -> None:
    """Writes the top-down trajectory picture (PNG, atomically)."""
    fig, ax = plt.subplots(figsize=(8, 7))
    handles = draw_trajectory(ax, rec)
    ax.legend(handles=handles, loc="upper left", bbox_to_anchor=(1.01, 1), fontsize=7)
    ax.set_title(_title(rec), fontsize=9)
    topdown.save_figure(fig, path)


def depth_image(depth: np.ndarray, max_depth: float = 10.0) -> np.ndarray:
    """(H, W) metres -> (H, W, 3) uint8, near bright, far dark (magma), clipped at
    ``max_depth`` (the policy network's depth scale)."""
    v = 1.0 - np.clip(depth / max_depth, 0.0, 1.0)
    return (matplotlib.colormaps["magma"](v)[..., :3] * 255).astype(np.uint8)


def save_preview(rec: EpisodeRecord, path: str | os.PathLike, frames: int = 3) -> None:
    """Writes a picture of a record: top-down trajectory beside first-person
    segmentation and depth at ``frames`` evenly spaced steps."""
    ks = np.linspace(0, rec.num_steps, frames).round().astype(int)
    fig = plt.figure(figsize=(4.6 + 2.6 * frames, 4.6), layout="constrained")
    grid = fig.add_gridspec(2, frames + 1, width_ratios=[1.7] + [1.0] * frames)
    ax = fig.add_subplot(grid[:, 0])
    fig.legend(handles=draw_trajectory(ax, rec), loc="outside lower left", ncol=3, fontsize=7, frameon=False)
    ax.set_title(_title(rec), fontsize=9)
    for c, k in enumerate(ks):
        for r, (img, name) in enumerate(((record.colorize(rec.segmentation[k]), "segmentation"),
                                         (depth_image(rec.depth[k]), "depth"))):
            a = fig.add_subplot(grid[r, c + 1])
            a.imshow(img, interpolation="nearest")
            a.set_xticks([])
            a.set_yticks([])
            if r == 0:
                sub = rec.subtargets[k]
                a.set_title(f"step {k}" + (f"\nsub-target {sub}" if sub else ""), fontsize=8)
            if c == 0:
                a.set_ylabel(name, fontsize=8)
    shown = np.unique(rec.segmentation[ks])
    handles = [matplotlib.patches.Patch(color=record.SEG_PALETTE[i] / 255, label=rooms.SEG_CLASSES[i].replace("_", " "))
               for i in shown]
    fig.legend(handles=handles, loc="outside lower right", ncol=min(len(handles), 7), fontsize=7, frameon=False)
    topdown.save_figure(fig, path)


class _TopdownCanvas:
    """The house drawn once; trajectories are painted per frame in pixel space."""

    def __init__(self, rec: EpisodeRecord, height: int):
        x0, y0, x1, y1 = rec.house.lot
        aspect = float(np.clip((x1 - x0 + 1) / (y1 - y0 + 1), 1.0, 2.0))
        fig = plt.figure(figsize=(height / 100 * aspect, height / 100), dpi=100)
        ax = fig.add_axes((0.02, 0.02, 0.96, 0.96))
        topdown.draw_house(ax, rec.house, furniture_labels=False, room_labels=True)
        ax.set_axis_off()
        fig.canvas.draw()
        self.image = np.asarray(fig.canvas.buffer_rgba())[..., :3].copy()
        h = self.image.shape[0]
        pix = ax.transData.transform(rec.poses[:, :2])
        self.points = np.stack([pix[:, 0], h - pix[:, 1]], axis=1)
        self.scale = ax.transData.transform((1.0, 0.0))[0] - ax.transData.transform((0.0, 0.0))[0]
        plt.close(fig)
        self.colors = [tuple(int(255 * c) for c in SUBTARGET_COLORS.get(s, _NO_SUBTARGET_COLOR))
                       for s in rec.subtargets]
        self.yaws = rec.poses[:, 2]

    def frame(self, k: int) -> np.ndarray:
        img = Image.fromarray(self.image)
        draw = ImageDraw.Draw(img)
        for i in range(1, k + 1):
            draw.line([tuple(self.points[i - 1]), tuple(self.points[i])], fill=self.colors[i], width=3)
        x, y = self.points[k]
        r = 0.25 * self.scale
        draw.ellipse([x - r, y - r, x + r, y + r], fill=(255, 0, 255), outline=(0, 0, 0))
        tip = (x + 2.5 * r * np.cos(self.yaws[k]), y - 2.5 * r * np.sin(self.yaws[k]))
        draw.line([(x, y), tip], fill=(0, 0, 0), width=3)
        return np.asarray(img)


def video_frames(rec: EpisodeRecord):
    """Frames of the side-by-side video: segmentation over depth, then the top-down view."""
    h, w = rec.segmentation.shape[1:]
    view_h = 2 * _UPSCALE * h
    canvas = _TopdownCanvas(rec, view_h)
    font = ImageFont.load_default(size=15)
    for k in range(rec.num_steps + 1):
        seg = np.kron(record.colorize(rec.segmentation[k]), np.ones((_UPSCALE, _UPSCALE, 1), np.uint8))
        dep = np.kron(depth_image(rec.depth[k]), np.ones((_UPSCALE, _UPSCALE, 1), np.uint8))
        top = canvas.frame(k)
        frame = np.concatenate([np.concatenate([seg, dep], axis=0), top[:view_h]], axis=1)
        img = Image.fromarray(frame)
        draw = ImageDraw.Draw(img)
        action = rec.steps[k - 1]["action_name"] if k else "start"
        sub = rec.subtargets[k]
        label = dict(font=font, fill=(255, 255, 255), stroke_width=2, stroke_fill=(0, 0, 0))
        draw.text((6, 4), f"step {k}: {action}" + (f"\nsub-target {sub}" if sub else ""), **label)
        draw.text((seg.shape[1] + 6, 4), f"target {rec.target}", **label)
        # Even sizes (16-pixel blocks) keep video codecs happy.
        fh, fw = frame.shape[:2]
        out = np.full((-(-fh // 16) * 16, -(-fw // 16) * 16, 3), 255, np.uint8)
        out[:fh, :fw] = np.asarray(img)
        yield out


def has_ffmpeg() -> bool:
    """Whether imageio can write MP4 (the imageio-ffmpeg package is installed)."""
    return importlib.util.find_spec("imageio_ffmpeg") is not None


def save_video(rec: EpisodeRecord, path: str | os.PathLike, fps: int = 10) -> pathlib.Path:
    """Writes the side-by-side video as MP4 (needs imageio-ffmpeg) or GIF.

    Without imageio-ffmpeg an ``.mp4`` request writes a GIF beside it and says
    so on stderr.

    Returns:
      The file written.
    """
    path = pathlib.Path(path)
    if path.suffix not in (".mp4", ".gif"):
        raise ValueError(f"video path {str(path)!r}: expected a .mp4 or .gif file")
    if path.suffix == ".mp4" and not has_ffmpeg():
        gif = path.with_suffix(".gif")
        print(f"imageio-ffmpeg is not installed (pip install imageio-ffmpeg): writing a GIF to {gif} instead of "
              f"{path}", file=sys.stderr)
        path = gif
    frames = list(video_frames(rec))
    if path.suffix == ".mp4":
        files.write_atomic_with(path, lambda tmp: imageio.mimwrite(
            tmp, frames, format="FFMPEG", fps=fps, codec="libx264", quality=7, macro_block_size=16))
    else:
        files.write_atomic_with(
            path, lambda tmp: imageio.mimwrite(tmp, frames, format="GIF", duration=1000 / fps, loop=0))
    return path


# -- recovery ---------------------------------------------------------------------

def recover(src: str | os.PathLike, dst: str | os.PathLike) -> int:
    """Salvages the complete chunks of a truncated record into a valid MCAP file.

    Returns:
      The number of messages written.

    Raises:
      ValueError: if ``src`` is not MCAP or nothing can be salvaged.
    """
    from mcap import records as r

    src, dst = pathlib.Path(src), pathlib.Path(dst)
    if not src.is_file():
        raise ValueError(f"{str(src)!r} does not exist or is not a file")
    with open(src, "rb") as f:
        if f.read(len(_MAGIC)) != _MAGIC:
            raise ValueError(f"{str(src)!r} is not an MCAP file (it does not start with the MCAP magic bytes)")
    recs = list(_iter_complete_records(src))
    count = sum(isinstance(x, r.Message) for x in recs)
    if not count:
        raise ValueError(f"{str(src)!r}: no complete chunk of messages to salvage")

    def write(tmp):
        with open(tmp, "wb") as f:
            w = Writer(f)
            header = next((x for x in recs if isinstance(x, r.Header)), r.Header(profile="", library=""))
            w.start(profile=header.profile, library=header.library)
            schemas, channels = {0: 0}, {}
            for x in recs:
                if isinstance(x, r.Schema) and x.id not in schemas:
                    schemas[x.id] = w.register_schema(x.name, x.encoding, x.data)
                elif isinstance(x, r.Channel) and x.id not in channels:
                    channels[x.id] = w.register_channel(x.topic, x.message_encoding, schemas[x.schema_id],
                                                        x.metadata)
                elif isinstance(x, r.Message):
                    w.add_message(channels[x.channel_id], x.log_time, x.data, x.publish_time, x.sequence)
                elif isinstance(x, r.Attachment):
                    w.add_attachment(x.create_time, x.log_time, x.name, x.media_type, x.data)
                elif isinstance(x, r.Metadata):
                    w.add_metadata(x.name, x.metadata)
            w.finish()

    files.write_atomic_with(dst, write)
    return count


# -- CLI --------------------------------------------------------------------------

def main(argv: Sequence[str] | None = None) -> int:
    parser = argparse.ArgumentParser(prog="python -m leaps_mj.replay", description=__doc__.split("\n\n")[0])
    parser.add_argument("file", help="an episode record (.mcap)")
    media = parser.add_mutually_exclusive_group()
    media.add_argument("--video", metavar="OUT.mp4", help="first-person + top-down video (MP4 needs imageio-ffmpeg)")
    media.add_argument("--gif", metavar="OUT.gif", help="the same video as an animated GIF")
    parser.add_argument("--fps", type=int, default=10, help="video frames per second (default 10 = real time)")
    parser.add_argument("--topdown", metavar="OUT.png", help="trajectory coloured by sub-target on the house")
    parser.add_argument("--preview", metavar="OUT.png", help="top-down view beside first-person frames")
    parser.add_argument("--recover", metavar="OUT.mcap", help="salvage a truncated record's complete chunks")
    args = parser.parse_args(argv)
    try:
        if args.recover:
            n = recover(args.file, args.recover)
            print(f"recovered {n} messages into {args.recover}")
            return 0
        rec = load(args.file)
        print(summary(rec))
        if args.topdown:
            save_topdown(rec, args.topdown)
            print(f"wrote {args.topdown}")
        if args.preview:
            save_preview(rec, args.preview)
            print(f"wrote {args.preview}")
        if args.video or args.gif:
            if args.gif and pathlib.Path(args.gif).suffix != ".gif":
                raise ValueError(f"--gif {args.gif!r}: expected a .gif file")
            print(f"wrote {save_video(rec, args.video or args.gif, fps=args.fps)}")
    except ValueError as e:
        parser.exit(2, f"{parser.prog}: error: {e}\n")
    return 0


if __name__ == "__main__":
    sys.exit(main())
