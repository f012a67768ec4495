"""Episode records: MCAP round trip, determinism, keep modes, crash recovery, replay."""

import json

import numpy as np
import pytest
from mcap.reader import make_reader
from mcap.writer import Writer
from mcap_protobuf.decoder import DecoderFactory

import leaps_mj
from leaps_mj.environment import episodes, expert
from leaps_mj.planning import semantic
from leaps_mj.records import recorder as record
from leaps_mj.records import replay
from leaps_mj.world import rooms, topdown

HORIZON = 25


@pytest.fixture(scope="module")
def env(tiny_dataset):
    e = leaps_mj.load(str(tiny_dataset), "test", seed=0, horizon=HORIZON, width=40, height=30, reward="sparse")
    yield e
    e.close()


@pytest.fixture(scope="module")
def specs(tiny_dataset):
    return episodes.load_split(str(tiny_dataset), "test")


def fake_info(spec, k):
    """An agent's info(): the reference posterior, a two-hop plan, a sub-target that changes once."""
    sub = "indoor" if k < 5 else spec.target
    return {"subtarget": sub, "plan": [sub, spec.target] if sub != spec.target else [spec.target],
            "belief": semantic.SemanticModel.from_reference().posterior()}


def run_episode(env, spec, rec, pass_first=False, success_only=False):
    """Runs the geodesic expert on ``spec`` under ``rec``; returns the observations (frame 0 first)."""
    ts = env.reset_to(spec)
    agent = expert.GeodesicExpert(env, seed=0)
    rec.begin(env, spec)
    if pass_first:
        rec.step(ts)
    observations, k = [ts.observation], 0
    while not ts.last():
        action = agent.act()
        ts = env.step(action)
        k += 1
        rec.step(ts, action, fake_info(spec, k))
        observations.append(ts.observation)
    return observations, rec.end({"success": bool(ts.discount == 0.0)} if success_only else None)


@pytest.fixture(scope="module")
def recorded(env, specs, tmp_path_factory):
    """One recorded episode in small chunks (so a cut file keeps some): (path, observations, spec)."""
    out = tmp_path_factory.mktemp("records") / "episode.mcap"
    spec = specs[0]
    with record.EpisodeRecorder(out, env, run_config={"agent": "expert", "horizon": HORIZON},
                                chunk_size=16 * 1024) as rec:
        observations, path = run_episode(env, spec, rec)
    return path, observations, spec


def read_all(path):
    with open(path, "rb") as f:
        reader = make_reader(f, validate_crcs=True)
        summary = reader.get_summary()
        messages = [(c.topic, s.name if s else None, m.log_time, m.data) for s, c, m in reader.iter_messages()]
        attachments = {a.name: a.data for a in reader.iter_attachments()}
        metadata = {m.name: m.metadata for m in reader.iter_metadata()}
    return summary, messages, attachments, metadata


def test_round_trip_topics_counts_times(recorded):
    path, observations, spec = recorded
    assert path.exists() and not path.with_name(path.name + ".part").exists()
    summary, messages, attachments, metadata = read_all(path)
    steps = len(observations) - 1
    schemas = {c.topic: summary.schemas[c.schema_id].name for c in summary.channels.values()}
    assert schemas[record.SEGMENTATION] == schemas[record.DEPTH] == "foxglove.RawImage"
    assert schemas[record.TF] == "foxglove.FrameTransforms"
    assert schemas[record.POSE] == "foxglove.PoseInFrame"
    assert schemas[record.HOUSE] == schemas[record.BELIEF_GRAPH] == "foxglove.SceneUpdate"
    assert schemas[record.STEP] == "leaps_mj.Step"
    counts = summary.statistics.channel_message_counts
    by_topic = {c.topic: counts[c.id] for c in summary.channels.values()}
    for topic in (record.SEGMENTATION, record.DEPTH, record.TF, record.POSE, record.SEMANTIC):
        assert by_topic[topic] == steps + 1, topic
    assert by_topic[record.STEP] == steps
    assert by_topic[record.BELIEF] == by_topic[record.BELIEF_GRAPH] == 2  # the sub-target changes once
    assert by_topic[record.HOUSE] == by_topic[record.EPISODE] == by_topic[record.OUTCOME] == 1
    for topic in by_topic:
        times = [t for top, _, t, _ in messages if top == topic]
        assert times == sorted(times), topic
    seg_times = [t for top, _, t, _ in messages if top == record.SEGMENTATION]
    assert seg_times == [k * record.STEP_NS for k in range(steps + 1)]
    assert set(attachments) == {f"{spec.house}.xml", f"{spec.house}.json", "run_config.json"}
    assert json.loads(attachments["run_config.json"]) == {"agent": "expert", "horizon": HORIZON}
    assert metadata["episode"]["target"] == spec.target
    assert json.loads(metadata["outcome"]["steps"]) == steps


def test_house_scene_matches_the_house(recorded, env):
    path, _, spec = recorded
    with open(path, "rb") as f:
        reader = make_reader(f, decoder_factories=[DecoderFactory()])
        (_, _, _, scene), = reader.iter_decoded_messages(topics=[record.HOUSE])
    entities = {e.id: e for e in scene.entities}
    house = env.house_model(spec.house).house

    def footprints(entity):
        return {tuple(np.round([c.pose.position.x - c.size.x / 2, c.pose.position.y - c.size.y / 2,
                                c.pose.position.x + c.size.x / 2, c.pose.position.y + c.size.y / 2], 3))
                for c in entity.cubes}

    for w in house.walls:
        assert tuple(np.round(w.rect, 3)) in footprints(entities[f"house/{w.cls}"]), w
    floors = {tuple(np.round(r.rect, 3)): topdown.ROOM_COLORS[r.type] for r in house.rooms}
    for c in entities["house/floor"].cubes:
        rect = tuple(np.round([c.pose.position.x - c.size.x / 2, c.pose.position.y - c.size.y / 2,
                               c.pose.position.x + c.size.x / 2, c.pose.position.y + c.size.y / 2], 3))
        np.testing.assert_allclose([c.color.r, c.color.g, c.color.b], floors[rect], atol=1e-6)
    n_geoms = sum(len(it.geoms) for it in house.items)
    furniture = entities["house/furniture"]
    assert len(furniture.cubes) + len(furniture.cylinders) + len(furniture.spheres) == n_geoms
    assert entities["agent"].frame_id == "agent" and entities["agent"].frame_locked


def test_decoded_images_equal_observations(recorded):
    path, observations, _ = recorded
    rec = replay.load(path)
    assert rec.num_steps == len(observations) - 1
    np.testing.assert_array_equal(rec.segmentation, np.stack([o["segmentation"] for o in observations]))
    np.testing.assert_array_equal(rec.depth, np.stack([o["depth"] for o in observations]))
    np.testing.assert_allclose(rec.poses[:, :2], np.stack([o["pose"][:2] for o in observations]), atol=1e-6)
    assert rec.subtargets[1:5] == ["indoor"] * 4 and rec.subtargets[-1] == rec.target
    assert rec.outcome["subtargets"] == ["indoor", rec.target]


def test_palette_round_trip_and_unknown_colour():
    ids = np.arange(rooms.NUM_SEG_CLASSES, dtype=np.uint8).reshape(5, 7)
    np.testing.assert_array_equal(record.decolorize(record.colorize(ids)), ids)
    rgb = record.colorize(ids)
    rgb[0, 0] = (1, 2, 3)
    with pytest.raises(ValueError, match="not a segmentation class colour"):
        record.decolorize(rgb)


def test_same_episode_same_payloads_with_either_first_frame_convention(env, specs, tmp_path):
    a, b = tmp_path / "a.mcap", tmp_path / "b.mcap"
    run_episode(env, specs[1], record.EpisodeRecorder(a, env))
    run_episode(env, specs[1], record.EpisodeRecorder(b, env), pass_first=True)
    payload = lambda p: [(t, s, lt, d) for t, s, lt, d in read_all(p)[1]]  # noqa: E731
    assert payload(a) == payload(b)


def test_keep_failures_and_sample(env, specs, tmp_path):
    rec = record.EpisodeRecorder(tmp_path / "fail", env, keep="failures")
    results = [run_episode(env, s, rec, success_only=True) for s in specs[2:6]]
    kept = sorted(p.name for p in (tmp_path / "fail").iterdir())
    failed = [p.name for _, p in results if p is not None]
    assert 0 < len(failed) < len(results), "the episodes should mix successes and failures"
    assert kept == sorted(failed)
    for p in (tmp_path / "fail").iterdir():
        assert replay.load(p).outcome["success"] is False

    # sample:K keeps the K smallest keys, whatever the order the episodes come in.
    keys = sorted(record.episode_key(s, "agent", seed=3) for s in specs[:6])
    for name, order in (("forward", specs[:6]), ("backward", specs[5::-1])):
        rec = record.EpisodeRecorder(tmp_path / name, keep="sample:2", seed=3)
        written = [run_episode(env, s, rec)[1] for s in order]
        files = sorted((tmp_path / name).iterdir())
        assert sorted(f.name[-21:-5] for f in files) == keys[:2]
        assert sum(p is not None for p in written) >= 2


def test_bad_modes_and_protocol_misuse(env, specs, tmp_path):
    for mode in ("some", "sample:0", "sample:x"):
        with pytest.raises(ValueError, match="record mode"):
            record.EpisodeRecorder(tmp_path, keep=mode)
    with pytest.raises(ValueError, match="expected a directory"):
        record.recorder_for_evaluation(tmp_path / "x.mcap")
    with pytest.raises(ValueError, match="expected a directory"):
        record.EpisodeRecorder(tmp_path / "x.mcap", keep="sample:3")
    rec = record.EpisodeRecorder(tmp_path / "one.mcap", env)
    ts = env.reset_to(specs[0])
    with pytest.raises(ValueError, match="call begin"):
        rec.step(ts)
    rec.begin()
    with pytest.raises(ValueError, match="call end"):
        rec.begin()
    with pytest.raises(ValueError, match="needs the action"):
        rec.step(env.step(0))
    with pytest.raises(ValueError, match="shape"):
        rec.step(env.step(0), 0, {"belief": np.zeros((8, 8))})
    rec.close()
    assert (tmp_path / "one.mcap.part").exists() and not (tmp_path / "one.mcap").exists()
    with pytest.raises(ValueError, match="one episode"):
        rec.begin()


def test_truncated_file_is_reported_and_recoverable(recorded, tmp_path):
    path, observations, _ = recorded
    data = path.read_bytes()
    cut = tmp_path / "cut.mcap.part"
    cut.write_bytes(data[: len(data) * 2 // 3])
    with pytest.raises(ValueError, match="truncated.*--recover"):
        replay.load(cut)
    fixed = tmp_path / "fixed.mcap"
    assert replay.recover(cut, fixed) > 0
    rec = replay.load(fixed)
    assert rec.outcome == {"complete": False}
    assert 0 < rec.num_steps < len(observations) - 1
    kept = observations[: rec.num_steps + 1]
    np.testing.assert_array_equal(rec.segmentation, np.stack([o["segmentation"] for o in kept]))


def test_not_mcap_corrupt_and_foreign_files(recorded, tmp_path):
    path, _, _ = recorded
    junk = tmp_path / "junk.mcap"
    junk.write_bytes(np.random.default_rng(0).integers(0, 256, 5000, dtype=np.uint8).tobytes())
    with pytest.raises(ValueError, match="not an MCAP file"):
        replay.load(junk)
    with pytest.raises(ValueError, match="not an MCAP file"):
        replay.recover(junk, tmp_path / "out.mcap")
    data = bytearray(path.read_bytes())
    chunks = read_all(path)[0].chunk_indexes
    middle = chunks[len(chunks) // 2].chunk_start_offset + 100  # inside a chunk of messages
    data[middle:middle + 64] = np.random.default_rng(1).integers(0, 256, 64, dtype=np.uint8).tobytes()
    corrupt = tmp_path / "corrupt.mcap"
    corrupt.write_bytes(bytes(data))
    with pytest.raises(ValueError, match="corrupt"):
        replay.load(corrupt)
    foreign = tmp_path / "foreign.mcap"
    with open(foreign, "wb") as f:
        w = Writer(f)
        w.start()
        ch = w.register_channel("/chatter", "json", w.register_schema("x", "jsonschema", b"{}"))
        w.add_message(ch, 0, b"{}", 0)
        w.finish()
    with pytest.raises(ValueError, match="lacks the channels"):
        replay.load(foreign)
    with pytest.raises(ValueError, match="does not exist"):
        replay.load(tmp_path / "missing.mcap")


def test_replay_cli(recorded, tmp_path, capsys, monkeypatch):
    path, observations, spec = recorded
    top, preview, gif = tmp_path / "top.png", tmp_path / "preview.png", tmp_path / "ep.gif"
    assert replay.main([str(path), "--topdown", str(top), "--preview", str(preview), "--gif", str(gif)]) == 0
    out = capsys.readouterr().out
    assert spec.house in out and spec.target in out and f"{len(observations) - 1} steps" in out
    assert "indoor -> " + spec.target in out
    for p in (top, preview, gif):
        assert p.read_bytes()[:4] in (b"\x89PNG", b"GIF8")
    monkeypatch.setattr(replay, "has_ffmpeg", lambda: False)
    assert replay.main([str(path), "--video", str(tmp_path / "ep.mp4")]) == 0
    assert "writing a GIF" in capsys.readouterr().err
    assert (tmp_path / "ep.gif").exists() and not (tmp_path / "ep.mp4").exists()
    junk = tmp_path / "junk.txt"
    junk.write_text("hello")
    with pytest.raises(SystemExit) as e:
        replay.main([str(junk)])
    assert e.value.code == 2 and "not an MCAP file" in capsys.readouterr().err
