"""Tests for prior learning by random exploration and the observation-noise search."""

import dataclasses
import json
import re

import numpy as np
import pytest

from leaps_mj.evaluation import tune_obs_noise
from leaps_mj.learning import train_prior
from leaps_mj.planning import semantic
from leaps_mj.world import rooms


def test_count_run_counts_present_pairs_from_the_start_node():
    pos = np.zeros((9, 9), dtype=np.int64)
    trials = np.zeros((9, 9), dtype=np.int64)
    kitchen, dining, garage, indoor = (rooms.room_index(r) for r in ("kitchen", "dining_room", "garage", "indoor"))
    seen = np.zeros(9, dtype=bool)
    seen[[kitchen, dining, rooms.room_index("office")]] = True  # office is not in this house
    train_prior.count_run(pos, trials, kitchen, [kitchen, dining, garage, indoor], seen)
    assert trials[kitchen].tolist() == [int(j in (dining, garage, indoor)) for j in range(9)]
    assert pos[kitchen].tolist() == [int(j == dining) for j in range(9)]
    assert trials.sum() == 3 and pos.sum() == 1


def test_prior_config_rejects_bad_values():
    with pytest.raises(ValueError, match="trials"):
        train_prior.PriorConfig(trials=0)
    with pytest.raises(ValueError, match="floor"):
        train_prior.PriorConfig(floor=0.7)


def test_tiny_preset_end_to_end_and_resume(tiny_dataset, tmp_path, capsys):
    out = tmp_path / "prior"
    argv = ["--preset", "tiny", "--dataset", str(tiny_dataset), "--out", str(out)]
    assert train_prior.main(argv) == 0
    text = capsys.readouterr().out
    assert "rank correlation" in text and "(0 resumed" in text
    model = semantic.SemanticModel.from_json(out / "prior.json")
    assert (model.psi_obs0, model.psi_obs1) == (semantic.PAPER_PSI_OBS0, semantic.PAPER_PSI_OBS1)
    off = model.prior[~np.eye(9, dtype=bool)]
    assert off.min() >= 1e-4 and off.max() <= 1 - 1e-4 and np.ptp(off) > 0.1
    state = json.loads((out / "state.json").read_text())
    assert state["house"] == 3 and state["train_config"]["trials"] == 2
    assert (out / "prior.png").stat().st_size > 10_000
    first = (out / "prior.json").read_text()
    assert train_prior.main(argv) == 0
    assert "(3 resumed" in capsys.readouterr().out
    assert (out / "prior.json").read_text() == first
    # A run under other settings in the same folder is refused, naming the difference.
    with pytest.raises(ValueError, match="trials: saved 2, given 1"):
        train_prior.main(argv + ["--trials", "1"])


def test_killed_prior_run_resumes_to_the_same_counts(tiny_dataset, tmp_path):
    config = dataclasses.replace(train_prior.PRESETS["tiny"], dataset=str(tiny_dataset))
    whole = train_prior.learn(config, tmp_path / "whole", progress=False)
    part = train_prior.Trainer(config, tmp_path / "parts", progress=False)
    part.train(stop_after=1)
    assert part.iteration == 1 and not part.finished
    rest = train_prior.learn(config, tmp_path / "parts", progress=False)
    assert rest["resumed"] == 1
    assert (rest["pos"] == whole["pos"]).all() and (rest["trials"] == whole["trials"]).all()


def test_choose_prefers_the_best_then_the_paper_values():
    paper = (*tune_obs_noise.PAPER, 30)
    assert tune_obs_noise.choose({(0.01, 0.3, 30): 0.5, paper: 0.4}) == (0.01, 0.3, 30)
    assert tune_obs_noise.choose({(0.01, 0.3, 30): 0.5, paper: 0.5}) == paper
    assert tune_obs_noise.choose({(0.01, 0.3, 45): 0.5, (0.05, 0.3, 30): 0.5}) == (0.01, 0.3, 45)
    assert tune_obs_noise.choose({(*tune_obs_noise.PAPER, 45): 0.5, paper: 0.5}) == paper


def test_obs_noise_tiny_preset_writes_the_chosen_noise(tiny_dataset, tmp_path, capsys):
    out = tmp_path / "tune"
    out.mkdir()
    semantic.SemanticModel.from_reference().to_json(out / "prior.json")
    argv = ["--preset", "tiny", "--dataset", str(tiny_dataset), "--out", str(out)]
    assert tune_obs_noise.main(argv) == 0
    model = semantic.SemanticModel.from_json(out / "prior.json")
    assert (model.psi_obs0, model.psi_obs1, 30) in tune_obs_noise.PRESETS["tiny"].grid()
    np.testing.assert_allclose(model.prior, semantic.SemanticModel.from_reference().prior)
    table = (out / "obs_noise.md").read_text()
    assert table.count("\n| 0.") == 2 and table.count("**chosen**") == 1
    assert "chosen psi_obs0" in capsys.readouterr().out
    chosen = json.loads((out / "obs_noise.json").read_text())
    assert (chosen["psi_obs0"], chosen["psi_obs1"]) == (model.psi_obs0, model.psi_obs1)
    assert chosen["replan_every"] == 30 and chosen["rule"] == "paper"


def test_obs_noise_searches_n_and_the_release_rule(tiny_dataset, tmp_path):
    out = tmp_path / "tune"
    out.mkdir()
    semantic.SemanticModel.from_reference().to_json(out / "prior.json")
    argv = ["--preset", "tiny", "--dataset", str(tiny_dataset), "--out", str(out), "--psi-obs0", "0.001",
            "--replan-every", "10,20", "--rule", "release"]
    assert tune_obs_noise.main(argv) == 0
    table = (out / "obs_noise.md").read_text()
    assert "release rule" in table
    assert [line.split(" | ")[2] for line in table.splitlines()[2:]] == ["10", "20"]
    assert json.loads((out / "obs_noise.json").read_text())["replan_every"] in (10, 20)
    digest = next((out / "obs_noise").iterdir())
    assert sorted(d.name for d in digest.iterdir()) == ["N10", "N20"]
    rows = (digest / "N20" / "episodes_leaps-release-psi0.001-0.15.csv").read_text()
    assert rows.count("\n") > 1


def test_obs_noise_grid_options_override_the_preset(tiny_dataset, tmp_path):
    out = tmp_path / "tune"
    out.mkdir()
    semantic.SemanticModel.from_reference().to_json(out / "prior.json")
    argv = ["--preset", "tiny", "--dataset", str(tiny_dataset), "--out", str(out), "--psi-obs0", "0.002",
            "--psi-obs1", "0.5,0.7"]
    assert tune_obs_noise.main(argv) == 0
    model = semantic.SemanticModel.from_json(out / "prior.json")
    assert (model.psi_obs0, model.psi_obs1) in [(0.002, 0.5), (0.002, 0.7)]
    assert (out / "obs_noise.md").read_text().count("\n| 0.002 |") == 2


@pytest.mark.parametrize("bad, match", [(["--psi-obs1", "0.5,x"], "expected comma-separated numbers"),
                                        (["--psi-obs1", "1.5"], r"psi_obs1 grid \(1.5,\): expected probabilities"),
                                        (["--episodes-per-length", "0"], "episodes_per_length 0: expected"),
                                        (["--replan-every", "30,0"], r"replan_every grid \(30, 0\): expected"),
                                        (["--replan-every", "3.5"], "expected comma-separated integers"),
                                        (["--policy-dir", "x"], "--policy-dir 'x' needs --subpolicy learned")])
def test_obs_noise_bad_grid_options_are_refused_naming_the_value(bad, match, capsys):
    with pytest.raises(SystemExit):
        tune_obs_noise.main(["--preset", "tiny", *bad])
    assert re.search(match, capsys.readouterr().err)
