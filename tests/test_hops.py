"""Tests for the hop benchmark: the hop episodes, the paired test and ``python -m leaps_mj.evaluation.hops``."""

import csv
import dataclasses
import json
import shutil

import numpy as np
import pytest

from leaps_mj.environment import episodes, roomnav
from leaps_mj.evaluation import harness, hops, stats
from leaps_mj.learning import goal_policy, policies
from leaps_mj.world import rooms


@pytest.fixture(scope="module")
def hop_dataset(tiny_dataset):
    """The tiny dataset with hop episodes for its test split (3 starts per node and distance)."""
    eps, counts = episodes.generate_hops(str(tiny_dataset), "test", per_node=3, seed=0)
    episodes.write(episodes.episodes_path(str(tiny_dataset), "test", "hops"), eps)
    return tiny_dataset, eps, counts


def test_hop_episodes_are_deterministic(hop_dataset, tmp_path):
    dataset, eps, _ = hop_dataset
    again, _ = episodes.generate_hops(str(dataset), "test", per_node=3, seed=0)
    episodes.write(tmp_path / "again.jsonl", again)
    assert (tmp_path / "again.jsonl").read_bytes() == \
        episodes.episodes_path(str(dataset), "test", "hops").read_bytes()
    other, _ = episodes.generate_hops(str(dataset), "test", per_node=3, seed=1)
    assert [e.start for e in other] != [e.start for e in eps]
    assert episodes.load_split(str(dataset), "test", "hops") == eps


def test_hop_starts_are_at_the_door_distance_and_outside_the_node(hop_dataset):
    dataset, eps, counts = hop_dataset
    models = {hm.house.id: hm for hm in episodes.house_models(str(dataset), "test")}
    for e in eps:
        hm = models[e.house]
        room = hm.house.rooms[hm.room_at(e.start[:2])]
        assert room.type != e.target and hm.plan_length(room.id, e.target) == e.plan_length
        assert not hm.in_node(hm.semantic_bits(*e.start[:2]), rooms.room_index(e.target))
        assert e.geodesic == pytest.approx(hm.geodesic(e.start[:2], e.target), abs=1e-3)
    assert set(counts) == set(rooms.GRAPH_NODES)
    for node, per_d in counts.items():
        for d, c in per_d.items():
            assert c["episodes"] == (3 if c["houses"] else 0)
            assert c["episodes"] == sum(e.target == node and e.plan_length == d for e in eps)
            having = sum(node in hm.house.room_types for hm in models.values())
            assert c["houses"] <= having
    assert {e.plan_length for e in eps} == set(episodes.HOP_DISTANCES)


def test_bad_arguments_name_the_value(hop_dataset):
    dataset, _, _ = hop_dataset
    with pytest.raises(ValueError, match="per_node 0"):
        episodes.generate_hops(str(dataset), "test", per_node=0)
    with pytest.raises(ValueError, match=r"distances \(0, 1\)"):
        episodes.generate_hops(str(dataset), "test", per_node=2, distances=(0, 1))
    with pytest.raises(ValueError, match="unknown episode set 'loops'"):
        episodes.load_split(str(dataset), "test", "loops")
    with pytest.raises(ValueError, match="make_episodes.py --hops"):
        episodes.load_split(str(dataset), "valid", "hops")
    with pytest.raises(ValueError, match="episodes 'loops'"):
        harness.EvalConfig(episodes="loops")
    with pytest.raises(ValueError, match="policy_dir 'x' needs subpolicy 'learned'"):
        harness.EvalConfig(policy_dir="x")


def test_paired_test_is_the_exact_sign_test():
    t = stats.paired_test(np.array([1, 1, 1, 1, 1, 1, 1, 0]), np.array([0, 0, 0, 0, 0, 0, 1, 1]))
    assert (t["n"], t["a"], t["b"], t["a_only"], t["b_only"]) == (8, 7, 2, 6, 1)
    assert t["p"] == pytest.approx(0.125)  # 2 * P(X <= 1), X ~ Binomial(7, 1/2)
    assert stats.paired_test(np.ones(3), np.ones(3))["p"] == 1.0
    with pytest.raises(ValueError, match="shapes"):
        stats.paired_test(np.ones(3), np.ones(2))


def test_new_config_fields_keep_old_result_folders_valid(tmp_path):
    config = harness.EvalConfig()
    assert set(config.to_json()) == {"dataset", "split", "horizon", "subpolicy", "prior", "replan_every", "seed"}
    (tmp_path / "config.json").write_text(json.dumps(config.to_json()))
    harness._check_config(tmp_path, config)  # a folder written before the fields existed
    with pytest.raises(ValueError, match="other settings"):
        harness._check_config(tmp_path, harness.EvalConfig(episodes="hops"))


def _main(dataset, out, *extra):
    return hops.main(["--dataset", str(dataset), "--split", "test", "--horizon", "10", "20", "--subset", "smoke",
                      "--limit", "4", "--out", str(out), "--no-progress", *extra])


def test_main_runs_resumes_and_pairs_with_a_baseline(hop_dataset, tmp_path, monkeypatch, capsys):
    dataset, _, _ = hop_dataset
    base = tmp_path / "base"
    assert _main(dataset, base) == 0
    for label in ("pure", "oracle"):
        with open(base / f"episodes_{label}.csv") as f:
            rows = list(csv.DictReader(f))
        assert len(rows) == 4 and all(int(r["steps"]) <= 20 for r in rows)
    table = (base / "results.md").read_text()
    assert "| pure |" in table and "1 door, ≤ 10" in table and "## 2 doors, per node" in table
    assert (base / "hop_success.png").stat().st_size > 10_000
    summary = json.loads((base / "summary.json").read_text())
    assert summary["config"]["episodes"] == "hops"
    by_distance = summary["success"]["oracle"]["20"]
    assert sum(by_distance[d]["all"]["n"] for d in by_distance) == 4
    by_metres = summary["by_geodesic"]["oracle"]
    assert sum(r["n"] for bins in by_metres.values() for r in bins.values()) == 4
    assert "## By the start's geodesic distance, ≤ 20" in table
    capsys.readouterr()

    def no_more_episodes(*args, **kwargs):
        raise AssertionError("a finished episode was run again")

    monkeypatch.setattr(episodes, "run_episode", no_more_episodes)
    assert _main(dataset, base) == 0
    assert (base / "results.md").read_text() == table
    monkeypatch.undo()

    # The default sub-policy is the shipped map-goal one (as evaluate's); `cpu` names the shipped μ(θ), recorded
    # as no folder (left out of config.json), as the hop folders made before the names were.
    assert summary["config"]["policy_dir"] == "goal_cpu"
    assert _main(dataset, tmp_path / "mu", "--agent", "oracle", "--policy-dir", "cpu") == 0
    assert "policy_dir" not in json.loads((tmp_path / "mu" / "summary.json").read_text())["config"]
    # The shipped checkpoints by their path as a "new" folder: the same seeds give the same episodes, p = 1.
    new = tmp_path / "new"
    assert _main(dataset, new, "--agent", "pure", "--policy-dir", str(goal_policy.DEFAULT_DIR),
                 "--baseline", str(base)) == 0
    printed = capsys.readouterr().out
    assert "exact McNemar p = 1" in printed and "only here 0, only baseline 0" in printed
    paired = json.loads((new / "summary.json").read_text())["baseline"]["paired"]
    assert all(per["all"]["a"] == per["all"]["b"] for by_d in paired.values() for per in by_d.values())
    assert "## Paired with the baseline" in (new / "results.md").read_text()


def test_main_refuses_what_it_cannot_compare(hop_dataset, tmp_path, capsys):
    dataset, _, _ = hop_dataset
    assert _main(dataset, tmp_path / "a", "--policy-dir", str(tmp_path / "nothing")) == 2
    assert "holds no sub-policy checkpoint" in capsys.readouterr().err
    assert _main(dataset, tmp_path / "b", "--agent", "random", "--seed", "1") == 0
    capsys.readouterr()
    assert _main(dataset, tmp_path / "c", "--agent", "random", "--baseline", str(tmp_path / "b")) == 2
    assert "add it to --agent" in capsys.readouterr().err
    assert _main(dataset, tmp_path / "d", "--agent", "pure", "--baseline", str(tmp_path / "b")) == 2
    err = capsys.readouterr().err
    assert "not comparable" in err and "'seed': (1, 0)" in err
    assert not (tmp_path / "d").exists()  # refused before running anything


def test_the_large_hop_set_is_another_draw_run_and_paired_only_with_itself(hop_dataset, tmp_path, load_tool,
                                                                           capsys):
    dataset, eps, _ = hop_dataset
    tool = load_tool("make_episodes")
    assert tool.main(["--dataset", str(dataset), "--split", "test", "--hops", "--large", "--per-node", "3"]) == 0
    large = episodes.load_split(str(dataset), "test", "hops_large")
    again, _ = episodes.generate_hops(str(dataset), "test", per_node=3, seed=episodes.HOP_SETS["hops_large"][1])
    assert large == again and len(large) == len(eps) and [e.start for e in large] != [e.start for e in eps]
    assert episodes.load_split(str(dataset), "test", "hops") == eps  # the standard set is left as it was
    with pytest.raises(SystemExit):
        tool.main(["--dataset", str(dataset), "--large"])
    assert "--large need --hops" in capsys.readouterr().err
    assert _main(dataset, tmp_path / "large", "--agent", "pure", "--large") == 0
    assert json.loads((tmp_path / "large" / "summary.json").read_text())["config"]["episodes"] == "hops_large"
    rows = harness.read_rows(harness.csv_path(tmp_path / "large", "pure"))
    assert {(r["house"], r["target"], r["plan_length"]) for r in rows} <= {
        (e.house, e.target, e.plan_length) for e in large}
    assert _main(dataset, tmp_path / "standard", "--agent", "pure", "--baseline", str(tmp_path / "large")) == 2
    assert "'episodes': ('hops_large', 'hops')" in capsys.readouterr().err


def test_a_partial_checkpoint_folder_runs_on_its_nodes(hop_dataset, tmp_path, capsys):
    dataset, _, _ = hop_dataset
    folder = tmp_path / "kitchen_only"
    folder.mkdir()
    shutil.copy(policies.DEFAULT_DIR / "kitchen.pt", folder / "kitchen.pt")
    assert _main(dataset, tmp_path / "all", "--agent", "pure", "--policy-dir", str(folder)) == 2
    err = capsys.readouterr().err
    assert "has no checkpoint for nodes [" in err and "--nodes kitchen" in err
    assert _main(dataset, tmp_path / "kitchen", "--agent", "pure", "--policy-dir", str(folder),
                 "--nodes", "kitchen") == 0
    rows = harness.read_rows(harness.csv_path(tmp_path / "kitchen", "pure"))
    assert rows and {r["target"] for r in rows} == {"kitchen"}


def test_hop_actions_tool_counts_turn_reversals(hop_dataset, capsys, load_tool):
    """tools/hop_actions.py: the observable teacher rarely reverses a turn; bad counts are refused."""
    dataset = hop_dataset[0]
    tool = load_tool("hop_actions")
    assert tool.main(["--dataset", str(dataset), "--agent", "observable", "--every", "1", "--limit", "4"]) == 0
    out = capsys.readouterr().out
    assert out.startswith("4 one-door hop episodes") and "action shares:" in out
    reversed_, turns = (int(v) for v in out.split("turn reversals ")[1].split(" consecutive")[0].split(" of "))
    assert turns == 0 or reversed_ / turns < 0.25
    with pytest.raises(SystemExit):
        tool.main(["--dataset", str(dataset), "--every", "0"])


def test_hop_curve_tool_plots_shipped_results(load_tool, tmp_path, capsys, monkeypatch):
    """tools/hop_curve.py plots committed hop results; it refuses bad specs and runs of other episodes."""
    import pathlib

    tool = load_tool("hop_curve")
    out = tmp_path / "curve.png"
    results = pathlib.Path(__file__).resolve().parents[1] / "results"
    monkeypatch.chdir(results.parent)   # the printed table names the folders as given
    assert tool.main(["--run", "cpu=108000=results/hops_shipped_v2_test",
                      "--run", "cpu=180000=results/hops_shipped180k_v2_test", "--out", str(out)]) == 0
    printed = capsys.readouterr().out
    assert out.stat().st_size > 10_000
    assert "| cpu (results/hops_shipped_v2_test) | 108,000 | 23.7 | 40.4 | 3.3 | 8.9 |" in printed
    for bad in ("cpu=x=results/hops_shipped_v2_test", "cpu=1000=results/no_such_folder", "cpu=1000"):
        with pytest.raises(SystemExit):
            tool.main(["--run", bad, "--out", str(out)])
    assert "expected LABEL=SAMPLES=FOLDER" in capsys.readouterr().err
    with pytest.raises(SystemExit):   # test and valid episodes do not share a plot
        tool.main(["--run", "a=1=results/hops_shipped_v2_test", "--run", "b=2=results/hops_shipped_v2_valid",
                   "--out", str(out)])
    assert "ran other episodes" in capsys.readouterr().err


def test_hop_ladder_tool_draws_agents_of_committed_results_side_by_side(load_tool, tmp_path, capsys, monkeypatch):
    """tools/hop_ladder.py reads any agent of committed hop results; it refuses bad specs, absent agents and
    runs of other episodes."""
    import pathlib

    tool = load_tool("hop_ladder")
    out = tmp_path / "ladder.png"
    monkeypatch.chdir(pathlib.Path(__file__).resolve().parents[1])   # the printed table names the folders as given
    assert tool.main(["--run", "net=results/hops_shipped_v2_test", "--run",
                      "sensed=results/hops_oracle_map_sensed_v2_test#oracle-map-sensed", "--out", str(out)]) == 0
    printed = capsys.readouterr().out
    assert out.stat().st_size > 10_000
    assert "| net (results/hops_shipped_v2_test) | pure | 23.7 | 40.4 | 3.3 | 8.9 |" in printed
    assert ("| sensed (results/hops_oracle_map_sensed_v2_test) | oracle-map-sensed | 54.8 | 71.5 | 10.4 | 26.3 |"
            in printed)
    for bad, message in (("net", "expected LABEL=FOLDER"), ("net=results/no_such_folder", "holds no summary.json"),
                         ("net=results/hops_shipped_v2_test#frontier", "not a hop benchmark run of agent 'frontier'")):
        with pytest.raises(SystemExit):
            tool.main(["--run", bad, "--out", str(out)])
        assert message in capsys.readouterr().err
    with pytest.raises(SystemExit):   # test and valid episodes do not share a plot
        tool.main(["--run", "a=results/hops_shipped_v2_test", "--run", "b=results/hops_shipped_v2_valid",
                   "--out", str(out)])
    assert "ran other episodes" in capsys.readouterr().err


def test_hop_visibility_tool_splits_success_by_what_a_turn_shows(load_tool, hop_dataset, tmp_path, capsys):
    """tools/hop_visibility.py: groups cover the one-door hops; a target in the first frame is in view on turning;
    folders of other episodes are refused."""
    dataset, eps, _ = hop_dataset
    tool = load_tool("hop_visibility")
    group_of = tool.groups(str(dataset), "test", 1)
    assert set(group_of) == {i for i, s in enumerate(eps) if s.plan_length == 1}
    assert set(group_of.values()) <= set(tool.GROUPS)
    env = roomnav.load(str(dataset), "test", width=40, height=30)
    for i in group_of:
        if not rooms.SEE_OBJECTS.get(eps[i].target):
            assert group_of[i] == tool.GROUPS[2]
            continue
        env.reset_to(eps[i])
        if env.task.target_fraction > 0:
            assert group_of[i] == tool.GROUPS[0]
    env.close()
    assert hops.main(["--dataset", str(dataset), "--split", "test", "--agent", "oracle", "--out", str(tmp_path / "run"),
                      "--no-progress"]) == 0
    capsys.readouterr()
    assert tool.main(["--dataset", str(dataset), "--split", "test", str(tmp_path / "run")]) == 0
    out = capsys.readouterr().out
    assert f"{len(group_of)} hop episodes 1 door(s) away" in out and "| oracle |" in out
    assert tool.main(["--dataset", str(dataset), "--split", "valid", str(tmp_path / "run")]) == 2
    assert "expected the episodes 'hops' of" in capsys.readouterr().err


def test_hop_visibility_tool_groups_by_the_start_room(load_tool, hop_dataset, tmp_path, capsys):
    """tools/hop_visibility.py --by room / doors: every one-door hop in one group, named by the start room's type or
    its door count; an unknown grouping is refused."""
    dataset, eps, _ = hop_dataset
    tool = load_tool("hop_visibility")
    models = {hm.house.id: hm for hm in episodes.house_models(str(dataset), "test")}
    by_room, by_doors = (tool.groups(str(dataset), "test", 1, by) for by in ("room", "doors"))
    assert set(by_room) == set(by_doors) == {i for i, s in enumerate(eps) if s.plan_length == 1}
    for i in by_room:
        hm = models[eps[i].house]
        room = next(r for r in hm.house.rooms if r.id == hm.room_at(eps[i].start[:2]))
        assert by_room[i] == room.type != eps[i].target
        doors = sum(room.id in d.rooms for d in hm.house.doors)
        assert by_doors[i] == (f"{tool.MANY_DOORS}+ doors" if doors >= tool.MANY_DOORS else
                               "1 door" if doors == 1 else f"{doors} doors")
    with pytest.raises(ValueError, match="unknown grouping"):
        tool.groups(str(dataset), "test", 1, "colour")
    # --by way: turned to face its door on the way, a start has it ahead; turned away, behind; across, beside.
    by_way = tool.groups(str(dataset), "test", 1, "way")
    assert set(by_way) == set(by_room) and set(by_way.values()) <= set(tool.WAY_GROUPS)
    for i in list(by_way)[:4]:
        hm, (x, y, _) = models[eps[i].house], eps[i].start
        room, types = hm.room_at((x, y)), {r.id: r.type for r in hm.house.rooms}
        door = min((d for d in hm.house.doors if room in d.rooms and any(
            types[r] == eps[i].target for r in d.rooms if r != room)),
            key=lambda d: np.hypot(d.center[0] - x, d.center[1] - y))
        near = "≤ 3 m" if np.hypot(door.center[0] - x, door.center[1] - y) <= tool.NEAR_DOOR else "> 3 m"
        facing = np.arctan2(door.center[1] - y, door.center[0] - x)
        for turn, where in ((0.0, "ahead"), (np.pi / 2, "side"), (np.pi, "behind")):
            spec = dataclasses.replace(eps[i], start=(x, y, facing + turn))
            assert tool._start_room(hm, spec, "way") == f"{where}, {near}"
    assert hops.main(["--dataset", str(dataset), "--split", "test", "--agent", "oracle", "--out", str(tmp_path / "run"),
                      "--no-progress"]) == 0
    capsys.readouterr()
    assert tool.main(["--dataset", str(dataset), "--split", "test", "--by", "doors", str(tmp_path / "run")]) == 0
    header = capsys.readouterr().out.splitlines()[2]
    counts = [int(cell.split()[0].rstrip("+")) for cell in header.split("|")[3:-1]]
    assert counts == sorted(counts) and len(counts) == len(set(by_doors.values()))
    assert tool.main(["--dataset", str(dataset), "--split", "test", "--large", str(tmp_path / "run")]) == 2
    assert "expected the episodes 'hops_large'" in capsys.readouterr().err


def test_success_by_the_starts_geodesic_distance_bins_every_start_once():
    def row(episode, doors, metres, step):
        return {"episode": episode, "plan_length": doors, "geodesic": metres, "success_step": step, "steps": 60}

    table = {"pure": [row(0, 1, 2.0, 10), row(1, 1, 4.9, None), row(2, 1, 7.5, 50), row(3, 1, 31.0, None),
                      row(4, 2, 5.0, 70)],
             "oracle": [row(0, 1, 2.0, 5), row(1, 1, 4.9, 8), row(2, 1, 7.5, 20), row(3, 1, 31.0, 58),
                        row(4, 2, 5.0, 30)]}
    out = hops.by_geodesic(table, 60)
    assert list(out["pure"]["1"]) == ["0-5 m", "5-10 m", ">= 15 m"]  # the empty 10-15 m bin is left out
    assert [(r["n"], r["successes"]) for r in out["pure"]["1"].values()] == [(2, 1), (1, 1), (1, 0)]
    assert out["pure"]["2"]["5-10 m"]["successes"] == 0  # 70 steps is past the horizon
    assert out["oracle"]["1"][">= 15 m"]["successes"] == 1


def test_hop_paths_tool_draws_the_runs_the_folder_records(load_tool, hop_dataset, tmp_path, capsys):
    """tools/hop_paths.py: the drawn episodes are a seeded draw of those asked for, each re-run with the steps the
    folder records and the map-goal goals it chose; a folder whose runs the sub-policy no longer takes is refused."""
    dataset, eps, _ = hop_dataset
    tool = load_tool("hop_paths")
    run = tmp_path / "run"
    assert _main(dataset, run, "--agent", "pure", "--policy-dir", str(goal_policy.DEFAULT_DIR), "--nodes", "kitchen",
                 "bedroom") == 0
    capsys.readouterr()
    config = tool.folder_config(run, "hops", None)
    rows = harness.read_rows(run / "episodes_pure.csv")
    group_of = {r["episode"]: "any" for r in rows if r["plan_length"] == 1}
    picked = tool.choose(rows, group_of, None, "all", 60, 2, seed=0)
    assert picked == tool.choose(rows, group_of, None, "all", 60, 2, seed=0) and len(picked) == 2
    assert set(picked) <= set(group_of)
    runs = tool.trace(config, "pure", picked, {r["episode"]: r for r in rows})
    for i in picked:
        recorded = next(r for r in rows if r["episode"] == i)
        assert len(runs[i]["poses"]) == recorded["steps"] + 1 and runs[i]["goals"]
        assert np.allclose(runs[i]["poses"][0], eps[i].start, atol=1e-6)
    out = tmp_path / "paths.png"
    assert tool.main([str(run), "--outcome", "all", "--count", "2", "--horizon", "20", "--out", str(out)]) == 0
    assert out.stat().st_size > 20_000 and "wrote" in capsys.readouterr().out
    with pytest.raises(ValueError, match="no failed episode starts in a room of type 'attic'"):
        tool.choose(rows, group_of, "attic", "failed", 60, 2, seed=0)
    shifted = [{**r, "steps": r["steps"] + 1} if r["episode"] == picked[0] else r for r in rows]
    with pytest.raises(ValueError, match=f"episode {picked[0]} ran .* the folder records"):
        tool.trace(config, "pure", picked, {r["episode"]: r for r in shifted})
    assert tool.main([str(run), "--large", "--out", str(out)]) == 2
    assert "expected the episodes 'hops_large'" in capsys.readouterr().err
