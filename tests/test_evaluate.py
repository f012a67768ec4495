"""Tests for the evaluation harness: the episode loop, statistics, files, plots and resuming."""

import csv
import json

import numpy as np
import pytest

import leaps_mj
from leaps_mj.environment import episodes
from leaps_mj.evaluation import harness as evaluate
from leaps_mj.evaluation import stats
from leaps_mj.planning import agents


class Recorder:
    """An observer remembering the calls it got."""

    def __init__(self):
        self.calls = []

    def begin(self, env, spec, agent):
        self.calls.append(("begin", spec.target, agent.name))

    def step(self, timestep, action, info):
        self.calls.append(("step", action, info["subtarget"]))

    def end(self, result):
        self.calls.append(("end", result["success"]))


def test_run_episode_reports_and_calls_the_observer(tiny_dataset):
    spec = episodes.load_split(str(tiny_dataset), "test")[0]
    env = leaps_mj.load(str(tiny_dataset), "test", reward="sparse", horizon=300)
    try:
        obs = Recorder()
        result = episodes.run_episode(env, agents.OracleAgent(env), spec, 300, observer=obs)
        assert result["success"] and result["success_step"] == result["steps"] <= 300
        assert (result["house"], result["target"], result["plan_length"]) == (spec.house, spec.target,
                                                                             spec.plan_length)
        assert obs.calls[0] == ("begin", spec.target, "oracle") and obs.calls[-1] == ("end", True)
        assert len(obs.calls) == result["steps"] + 2
        short = episodes.run_episode(env, agents.RandomAgent(0), spec, 3)
        assert short["steps"] == 3 and short["success_step"] is None
        with pytest.raises(ValueError, match="exceeds the environment's horizon"):
            episodes.run_episode(env, agents.RandomAgent(0), spec, 301)
    finally:
        env.close()


def test_success_at_smaller_horizons_is_derived_from_the_success_step():
    rows = [{"success_step": 5}, {"success_step": None}, {"success_step": 50}]
    assert stats.success_at(rows, 10).tolist() == [True, False, False]
    assert stats.success_at(rows, 50).tolist() == [True, False, True]


def test_wilson_interval():
    low, high = stats.wilson(5, 10)
    assert (low, high) == pytest.approx((0.2366, 0.7634), abs=1e-4)
    assert stats.wilson(0, 20)[0] == 0.0
    assert np.isnan(stats.wilson(0, 0)[0])


def test_select_episodes_is_stratified_and_seeded(tiny_dataset):
    specs = episodes.load_split(str(tiny_dataset), "test")
    picked = episodes.select_episodes(specs, per_length=2, seed=3)
    lengths = [specs[i].plan_length for i in picked]
    assert picked == sorted(picked) and picked == episodes.select_episodes(specs, per_length=2, seed=3)
    assert all(lengths.count(L) == min(2, sum(s.plan_length == L for s in specs)) for L in set(lengths))
    assert episodes.select_episodes(specs, limit=4) == [0, 1, 2, 3]
    with pytest.raises(ValueError, match="per_length"):
        episodes.select_episodes(specs, per_length=0)


def _main(tiny_dataset, out, *extra):
    return evaluate.main(["--agent", "random", "pure", "leaps", "oracle", "--dataset", str(tiny_dataset),
                          "--split", "test", "--horizon", "20", "60", "--out", str(out), "--limit", "4",
                          "--prior", "reference", "--subpolicy", "local", "--no-progress", *extra])


def test_main_writes_csvs_table_plots_and_resumes(tiny_dataset, tmp_path, monkeypatch, capsys):
    out = tmp_path / "eval"
    assert _main(tiny_dataset, out) == 0
    for label in ("random", "pure", "leaps", "oracle"):
        with open(out / f"episodes_{label}.csv") as f:
            rows = list(csv.DictReader(f))
        assert [int(r["episode"]) for r in rows] == [0, 1, 2, 3]
        assert all(int(r["steps"]) <= 60 for r in rows)
    table = (out / "results.md").read_text()
    assert "| oracle |" in table and "H = 20" in table and "Relative improvement" in table
    assert "## Paired: leaps against pure on the same episodes" in table
    rows = {label: evaluate.read_rows(evaluate.csv_path(out, label)) for label in ("leaps", "pure")}
    test = stats.paired_test(stats.success_at(rows["leaps"], 60), stats.success_at(rows["pure"], 60))
    summary = json.loads((out / "summary.json").read_text())
    assert summary["paired"]["leaps"]["pure"]["60"]["all"] == test
    assert set(summary["paired"]["leaps"]) == {"random", "pure"}   # baselines only, not the oracle
    for name in ("success_vs_plan_length.png", "success_vs_metres.png", "relative_improvement.png"):
        assert (out / name).stat().st_size > 10_000
    assert "| leaps |" in capsys.readouterr().out

    def no_more_episodes(*args, **kwargs):
        raise AssertionError("a finished episode was run again")

    monkeypatch.setattr(episodes, "run_episode", no_more_episodes)
    assert _main(tiny_dataset, out) == 0
    assert (out / "results.md").read_text() == table
    assert _main(tiny_dataset, out, "--seed", "1") == 2  # other settings: refuse to mix
    assert "other settings" in capsys.readouterr().err


def test_results_do_not_depend_on_workers(tiny_dataset, tmp_path):
    specs = [evaluate.AGENTS["random"], evaluate.AGENTS["pure"]]
    config = evaluate.EvalConfig(dataset=str(tiny_dataset), split="test", horizon=40)
    one = evaluate.run(config, specs, [0, 1, 2], tmp_path / "one", progress=False)
    two = evaluate.run(config, specs, [0, 1, 2], tmp_path / "two", workers=2, chunk=1, progress=False)
    assert one == two
    for label in ("random", "pure"):  # files too: sorted by episode, whichever chunk finished first
        assert (tmp_path / "one" / f"episodes_{label}.csv").read_bytes() == \
            (tmp_path / "two" / f"episodes_{label}.csv").read_bytes()


def test_run_observed_repeats_the_evaluation_with_an_observer(tiny_dataset, tmp_path):
    """harness.run_observed: the rows the evaluation wrote, with the observer called on every step."""

    class Steps:
        def __init__(self):
            self.begun, self.steps, self.ended = 0, 0, 0

        def begin(self, env, spec, agent):
            self.begun += 1

        def step(self, timestep, action, info):
            self.steps += 1

        def end(self, result):
            self.ended += 1

    config = evaluate.EvalConfig(dataset=str(tiny_dataset), split="test", horizon=40)
    rows = evaluate.run(config, [evaluate.AGENTS["leaps"]], [1, 2], tmp_path / "eval", progress=False)["leaps"]
    observer = Steps()
    assert evaluate.run_observed(config, evaluate.AGENTS["leaps"], [1, 2], observer) == rows
    assert observer.begun == observer.ended == 2 and observer.steps == sum(r["steps"] for r in rows)


def test_casestudy_draws_the_episode(tiny_dataset, tmp_path, capsys):
    from leaps_mj.evaluation import casestudy

    out = tmp_path / "case.png"
    argv = ["--episode", "7", "--dataset", str(tiny_dataset), "--prior", "reference", "--horizon", "120",
            "--out", str(out)]
    assert casestudy.main(argv) == 0
    assert out.stat().st_size > 50_000
    assert "replans:" in capsys.readouterr().out
    assert casestudy.main(argv[:1] + ["999"] + argv[2:]) == 2


def test_main_records_episodes_as_mcap(tiny_dataset, tmp_path, capsys):
    from leaps_mj.records import replay

    out, rec = tmp_path / "eval", tmp_path / "records"
    code = evaluate.main(["--agent", "random", "leaps", "--dataset", str(tiny_dataset), "--split", "test",
                          "--horizon", "20", "--out", str(out), "--limit", "2", "--no-progress", "--subpolicy", "local",
                          "--record", str(rec), "--record-mode", "all"])
    assert code == 0
    for label in ("random", "leaps"):
        files = sorted((rec / label).glob("*.mcap"))
        assert len(files) == 2
        episode = replay.load(files[0])
        assert 1 <= episode.num_steps <= 20
    assert evaluate.main(["--agent", "random", "--dataset", str(tiny_dataset), "--out", str(tmp_path / "e2"),
                          "--record", str(rec), "--record-mode", "bogus"]) == 2
    assert "record mode 'bogus'" in capsys.readouterr().err


def test_learned_baselines_run_on_the_shipped_checkpoints(tiny_dataset, tmp_path):
    """aug (μ_s) and the controller over learned sub-policies: rows for every episode, the same on a rerun."""
    specs = [evaluate.AGENTS["aug"], evaluate.AGENTS["controller"]]
    config = evaluate.EvalConfig(dataset=str(tiny_dataset), split="test", horizon=30, subpolicy="learned")
    one = evaluate.run(config, specs, [0, 1], tmp_path / "one", progress=False)
    two = evaluate.run(config, specs, [0, 1], tmp_path / "two", workers=2, chunk=1, progress=False)
    assert one == two
    assert set(one) == {"aug", "controller"}
    for rows in one.values():
        assert [int(r["episode"]) for r in rows] == [0, 1] and all(int(r["steps"]) <= 30 for r in rows)


@pytest.mark.parametrize("extra, message", [
    (["--num-workers", "0"], "--workers/--num-workers 0"),
    (["--ray-address", "10.0.0.1:6379"], "--ray-address '10.0.0.1:6379' needs --backend ray"),
])
def test_bad_backend_options_are_usage_errors(tiny_dataset, tmp_path, capsys, extra, message):
    with pytest.raises(SystemExit) as e:
        _main(tiny_dataset, tmp_path / "eval", *extra)
    assert e.value.code == 2 and message in capsys.readouterr().err
    with pytest.raises(ValueError, match="backend 'dask'"):
        evaluate.run(evaluate.EvalConfig(), [], [], tmp_path / "x", backend="dask")


def test_leaps_prior_and_n_default_by_subpolicy(tiny_dataset, tmp_path):
    """Without --prior / --replan-every, LEAPS gets the shipped prior and N tuned for its sub-policy: one matrix,
    two noises; the paper's N = 30 for the local expert, a longer one for the map-goal network; given, they win."""
    local, learned = (agents.load_model(agents.SUBPOLICY_PRIORS[k]) for k in ("local", "learned"))
    np.testing.assert_array_equal(local.prior, learned.prior)
    assert learned.psi_obs1 > local.psi_obs1, "failures of the learned sub-policies say less about connectivity"
    assert agents.SUBPOLICY_REPLAN_EVERY == {"local": 30, "learned": 60}
    for subpolicy, name in agents.SUBPOLICY_PRIORS.items():
        out = tmp_path / subpolicy
        assert evaluate.main(["--agent", "leaps", "--dataset", str(tiny_dataset), "--split", "test", "--horizon", "5",
                              "--out", str(out), "--limit", "1", "--no-progress", "--subpolicy", subpolicy]) == 0
        config = json.loads((out / "config.json").read_text())
        assert (config["prior"], config["replan_every"]) == (name, agents.SUBPOLICY_REPLAN_EVERY[subpolicy])
    assert agents.subpolicy_defaults("learned", "reference", 45) == ("reference", 45)


def test_temperature_is_a_learned_subpolicy_option_left_out_of_config_json_at_one():
    assert "temperature" not in evaluate.EvalConfig(subpolicy="learned").to_json()
    assert evaluate.EvalConfig(subpolicy="learned", temperature=0.5).to_json()["temperature"] == 0.5
    with pytest.raises(ValueError, match="temperature 0.5 needs subpolicy 'learned', not 'local'"):
        evaluate.EvalConfig(subpolicy="local", temperature=0.5)
    with pytest.raises(ValueError, match="temperature 0: expected a positive number"):
        evaluate.EvalConfig(subpolicy="learned", temperature=0)


def test_main_runs_leaps_over_a_map_goal_sub_policy_from_policy_dir(tiny_dataset, tmp_path, capsys):
    """--policy-dir with a goal.pt drives LEAPS and pure with the map-goal sub-policy; a temperature is refused."""
    import torch

    from leaps_mj.learning import checkpoints, goal_policy, nets

    torch.manual_seed(0)
    config = nets.GoalNetConfig(width=24, height=18)
    checkpoints.save_checkpoint(tmp_path / "goal" / goal_policy.GOAL, nets.GoalNet(config), config, {})
    argv = ["--agent", "pure", "leaps", "--dataset", str(tiny_dataset), "--split", "test", "--horizon", "20",
            "--subpolicy", "learned", "--policy-dir", str(tmp_path / "goal"), "--limit", "2", "--no-progress"]
    assert evaluate.main(argv + ["--out", str(tmp_path / "eval")]) == 0
    saved = json.loads((tmp_path / "eval" / "config.json").read_text())
    assert saved["policy_dir"] == str(tmp_path / "goal")
    with open(tmp_path / "eval" / "episodes_leaps.csv") as f:
        assert len(list(csv.DictReader(f))) == 2
    assert evaluate.main(argv + ["--out", str(tmp_path / "hot"), "--temperature", "0.5"]) == 2
    assert "does not sample" in capsys.readouterr().err


def test_the_default_sub_policy_is_the_shipped_map_goal_one_and_shipped_folders_go_by_name(tiny_dataset, tmp_path):
    """Without --subpolicy / --policy-dir evaluation drives the shipped map-goal sub-policy (recorded by name);
    ``--policy-dir cpu``, the shipped μ(θ), is recorded as no folder, as result folders made before it was named."""
    from leaps_mj.learning import goal_policy, policies, policy_folder

    argv = ["--agent", "pure", "--dataset", str(tiny_dataset), "--split", "test", "--horizon", "5", "--limit", "1",
            "--no-progress"]
    assert evaluate.main(argv + ["--out", str(tmp_path / "default")]) == 0
    saved = json.loads((tmp_path / "default" / "config.json").read_text())
    assert (saved["subpolicy"], saved["policy_dir"]) == ("learned", policy_folder.DEFAULT)
    assert evaluate.main(argv + ["--out", str(tmp_path / "mu"), "--policy-dir", "cpu"]) == 0
    assert "policy_dir" not in json.loads((tmp_path / "mu" / "config.json").read_text())
    assert policy_folder.resolve("goal_cpu") == goal_policy.DEFAULT_DIR
    assert policy_folder.resolve("cpu") == policies.DEFAULT_DIR
    assert policy_folder.resolve(None) is None
    assert policy_folder.resolve(tmp_path) == tmp_path
    assert isinstance(policy_folder.load("goal_cpu"), goal_policy.GoalSubPolicy)
    assert policy_folder.controller_path("goal_cpu") == goal_policy.DEFAULT_DIR / policy_folder.CONTROLLER
    assert policy_folder.controller_path("cpu") == policy_folder.baselines.DEFAULT_CONTROLLER


def test_fig6_bits_tool_runs_the_ablations_on_a_draw_of_the_source_episodes(load_tool, tiny_dataset, tmp_path, capsys):
    """tools/fig6_bits.py: reuses the source's leaps / leaps-cnn rows on its draw, runs the two ablations there,
    pairs every classifier agent with the ground truth and the ablations with the classifier."""
    source, out = tmp_path / "source", tmp_path / "ablation"
    assert evaluate.main(["--agent", "leaps", "leaps-cnn", "--dataset", str(tiny_dataset), "--split", "test",
                          "--horizon", "20", "--out", str(source), "--limit", "6", "--prior", "reference",
                          "--subpolicy", "local", "--no-progress"]) == 0
    tool = load_tool("fig6_bits")
    rows = evaluate.read_rows(evaluate.csv_path(source, "leaps"))
    lengths = sorted({r["plan_length"] for r in rows})
    argv = ["--source", str(source), "--out", str(out), "--lengths", *map(str, lengths), "--workers", "1"]
    assert tool.main(argv + ["--per-length", "1", "--fp-episodes", "2"]) == 0
    counts = json.loads((out / "false_positives.json").read_text())
    assert counts["episodes"] == 2 and counts["steps"] > 0 and counts["same_as_evaluation"]
    assert counts["false_positives"] >= counts["neighbour_type"] >= counts["target_type_next_door"]
    assert counts["target_type"] >= counts["target_type_next_door"]
    picked = tool.subset(rows, 1, lengths, 0)
    assert len(picked) == len(lengths)
    for label in tool.AGENTS:
        assert [r["episode"] for r in evaluate.read_rows(evaluate.csv_path(out, label))] == picked
    for label in tool.REUSED:
        kept = [r for r in evaluate.read_rows(evaluate.csv_path(source, label)) if r["episode"] in picked]
        assert evaluate.read_rows(evaluate.csv_path(out, label)) == kept
    text = (out / "results.md").read_text()
    for a, b in (("leaps-cnn", "leaps"), ("leaps-cnn-and-truth", "leaps"), ("leaps-cnn-or-truth", "leaps-cnn")):
        assert f"## Paired: {a} against {b} on the same episodes" in text
    capsys.readouterr()
    assert tool.main(argv + ["--per-length", "99", "--out", str(tmp_path / "other")]) == 2
    assert "99 asked for" in capsys.readouterr().err
