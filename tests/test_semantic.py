"""Tests for the semantic model: posterior, observation rules, planning, I/O, plots."""

import json
import warnings

import matplotlib.figure
import numpy as np
import pytest

from leaps_mj.planning import semantic
from leaps_mj.planning.semantic import SemanticModel
from leaps_mj.world import rooms

PSI0, PSI1 = semantic.PAPER_PSI_OBS0, semantic.PAPER_PSI_OBS1
N = semantic.NUM_NODES
LIVING, GARAGE, OUTDOOR, INDOOR = (rooms.room_index(r) for r in ("living_room", "garage", "outdoor", "indoor"))


def make_prior(edges, background=0.01):
    """9x9 symmetric prior: `background` everywhere, `edges` {(i, j): p} on top."""
    prior = np.full((N, N), background)
    for (i, j), p in edges.items():
        prior[i, j] = prior[j, i] = p
    np.fill_diagonal(prior, 1.0)
    return prior


def expected_posterior(p, n_pos, n_neg):
    """P(z=1 | Y) by direct Bayes' rule on small counts."""
    one = p * (1 - PSI1) ** n_pos * PSI1**n_neg
    zero = (1 - p) * PSI0**n_pos * (1 - PSI0) ** n_neg
    return one / (one + zero)


# --- posterior ---------------------------------------------------------------


def test_posterior_without_observations_is_prior():
    model = SemanticModel.from_reference()
    np.testing.assert_allclose(model.posterior(), rooms.reference_prior(), rtol=1e-12)


@pytest.mark.parametrize("n_pos, n_neg", [(1, 0), (0, 1), (2, 3), (4, 1)])
def test_posterior_matches_hand_computation(n_pos, n_neg):
    model = SemanticModel(make_prior({(1, 2): 0.3}))
    for _ in range(n_pos):
        model.observe(1, 2, True)
    for _ in range(n_neg):
        model.observe("dining_room", "kitchen", False)
    post = model.posterior()
    assert post[1, 2] == pytest.approx(expected_posterior(0.3, n_pos, n_neg), rel=1e-12)
    assert post[2, 1] == post[1, 2]
    assert post[0, 1] == pytest.approx(0.01)  # other edges untouched


def test_one_positive_and_one_negative_by_hand():
    model = SemanticModel(make_prior({(3, 7): 0.3}))
    model.observe(3, 7, True)
    assert model.posterior()[3, 7] == pytest.approx(0.3 * 0.85 / (0.3 * 0.85 + 0.7 * 0.001))
    model.reset()
    model.observe(3, 7, False)
    assert model.posterior()[3, 7] == pytest.approx(0.3 * 0.15 / (0.3 * 0.15 + 0.7 * 0.999))


def test_posterior_is_symmetric_with_unit_diagonal():
    model = SemanticModel.from_reference()
    model.observe_bits([1, 0, 1, 0, 0, 1, 0, 0, 1])
    model.observe(4, 6, False)
    post = model.posterior()
    np.testing.assert_array_equal(post, post.T)
    np.testing.assert_array_equal(np.diag(post), np.ones(N))


def test_large_counts_do_not_overflow():
    model = SemanticModel.from_reference()
    model.n_pos[0, 8] = model.n_pos[8, 0] = 10**6
    model.n_neg[0, 8] = model.n_neg[8, 0] = 10**6
    model.n_neg[1, 2] = model.n_neg[2, 1] = 10**7
    model.n_pos[3, 6] = model.n_pos[6, 3] = 10**7
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        post = model.posterior()
        log_post = model.log_posterior()
    assert np.isfinite(post).all() and ((post >= 0) & (post <= 1)).all()
    assert np.isfinite(log_post).all()  # plan costs stay finite even when beliefs underflow
    assert post[1, 2] == 0.0 and post[3, 6] == 1.0


def test_reset_restores_prior():
    model = SemanticModel.from_reference()
    model.observe(0, 7, True)
    model.observe_bits(np.ones(N, dtype=bool))
    model.reset()
    assert not model.n_pos.any() and not model.n_neg.any()
    np.testing.assert_allclose(model.posterior(), model.prior)


# --- observation rules -------------------------------------------------------


def test_observe_bits_paper_rule():
    model = SemanticModel.from_reference()
    seen = np.zeros(N, dtype=bool)
    seen[[LIVING, GARAGE]] = True
    model.observe_bits(seen)
    assert model.n_pos[LIVING, GARAGE] == model.n_pos[GARAGE, LIVING] == 1  # both on
    assert model.n_pos.sum() == 2 and not np.diag(model.n_pos).any()
    assert model.n_neg[LIVING, OUTDOOR] == model.n_neg[OUTDOOR, GARAGE] == 1  # exactly one on
    assert model.n_neg[LIVING, GARAGE] == 0
    assert model.n_neg[OUTDOOR, INDOOR] == 0  # neither on: no observation
    assert model.n_neg.sum() == 2 * 2 * 7


def test_observe_bits_rejects_bad_vectors():
    model = SemanticModel.from_reference()
    with pytest.raises(ValueError, match=r"\(8,\)"):
        model.observe_bits(np.zeros(8, dtype=bool))
    with pytest.raises(ValueError, match="0.5"):
        model.observe_bits([0.5] + [0] * 8)


def test_seen_vector_accumulates_and_marks_indoor():
    history = np.zeros((4, 8), dtype=bool)
    history[0, LIVING] = True
    history[2, GARAGE] = True
    history[3, [GARAGE, OUTDOOR]] = True  # row 1 is all zero: untyped indoor space
    expected = np.zeros(N, dtype=bool)
    expected[[LIVING, GARAGE, OUTDOOR, INDOOR]] = True
    np.testing.assert_array_equal(semantic.seen_vector(history), expected)
    history[1, 0] = True
    assert not semantic.seen_vector(history)[INDOOR]
    assert not semantic.seen_vector(np.zeros((0, 8))).any()
    with pytest.raises(ValueError, match=r"\(3, 9\)"):
        semantic.seen_vector(np.zeros((3, 9)))


def test_observe_subtarget_outcome_is_one_edge_observation():
    model = SemanticModel.from_reference()
    model.observe_subtarget_outcome("living_room", "garage", reached=False)
    model.observe_subtarget_outcome(LIVING, OUTDOOR, reached=True)
    assert model.n_neg[LIVING, GARAGE] == model.n_neg[GARAGE, LIVING] == 1
    assert model.n_pos[LIVING, OUTDOOR] == model.n_pos[OUTDOOR, LIVING] == 1
    assert model.n_pos.sum() == model.n_neg.sum() == 2


def test_observe_rejects_bad_edges():
    model = SemanticModel.from_reference()
    with pytest.raises(ValueError, match="self-loop"):
        model.observe(2, "dining_room", True)
    with pytest.raises(ValueError, match="'attic'"):
        model.observe("attic", 0, True)
    with pytest.raises(ValueError, match="9"):
        model.observe(0, 9, True)
    with pytest.raises(ValueError, match="'yes'"):
        model.observe(0, 1, "yes")


# --- planning ----------------------------------------------------------------


def test_chain_beats_weak_direct_edge():
    model = SemanticModel(make_prior({(0, 1): 0.9, (1, 2): 0.9, (0, 2): 0.5}))
    assert model.plan(0, 2) == [0, 1, 2]
    assert model.next_subtarget([0], 2) == 1
    model = SemanticModel(make_prior({(0, 1): 0.9, (1, 2): 0.9, (0, 2): 0.85}))
    assert model.plan(0, 2) == [0, 2]


def test_ties_prefer_fewer_hops_then_smaller_sequence():
    # Two equally likely 2-hop routes 0-1-3 and 0-2-3: the smaller sequence wins.
    model = SemanticModel(make_prior({(0, 1): 0.6, (1, 3): 0.6, (0, 2): 0.6, (2, 3): 0.6}))
    assert model.plan(0, 3) == [0, 1, 3]
    # A direct edge as likely as a 2-hop route (0.25 = 0.5 * 0.5): fewer hops wins.
    model = SemanticModel(make_prior({(0, 1): 0.5, (1, 3): 0.5, (0, 3): 0.25}))
    assert model.plan(0, 3) == [0, 3]
    # Equal starts: the smaller start index wins, whatever the input order.
    model = SemanticModel(make_prior({(1, 3): 0.7, (2, 3): 0.7}))
    assert model.plan([2, 1], 3) == [1, 3]


def test_plan_when_already_at_target():
    model = SemanticModel.from_reference()
    assert model.plan(["kitchen", "indoor"], "indoor") == [INDOOR]
    assert model.next_subtarget("kitchen", "kitchen") == 1


def test_plan_rejects_bad_nodes():
    model = SemanticModel.from_reference()
    with pytest.raises(ValueError, match="'cellar'"):
        model.plan(["cellar"], "kitchen")
    with pytest.raises(ValueError, match="empty"):
        model.plan([], "kitchen")
    with pytest.raises(ValueError, match="-1"):
        model.plan(0, -1)


def test_failed_subtarget_makes_planner_reroute():
    model = SemanticModel(
        make_prior({(LIVING, GARAGE): 0.9, (GARAGE, OUTDOOR): 0.9, (LIVING, INDOOR): 0.5,
                    (INDOOR, OUTDOOR): 0.5, (LIVING, OUTDOOR): 0.1})
    )
    assert model.plan("living_room", "outdoor") == [LIVING, GARAGE, OUTDOOR]
    assert model.next_subtarget("living_room", "outdoor") == GARAGE
    for _ in range(3):
        model.observe_subtarget_outcome("living_room", "garage", reached=False)
    assert model.plan("living_room", "outdoor") in ([LIVING, INDOOR, OUTDOOR], [LIVING, OUTDOOR])
    assert model.next_subtarget("living_room", "outdoor") != GARAGE


def test_paper_rule_makes_planner_reroute():
    model = SemanticModel(
        make_prior({(LIVING, GARAGE): 0.9, (GARAGE, OUTDOOR): 0.9, (LIVING, INDOOR): 0.5,
                    (INDOOR, OUTDOOR): 0.9, (LIVING, OUTDOOR): 0.1})
    )
    assert model.plan("living_room", "outdoor") == [LIVING, GARAGE, OUTDOOR]
    seen = np.zeros(N, dtype=bool)
    seen[[LIVING, INDOOR]] = True  # went into the hallway, never saw the garage
    model.observe_bits(seen)
    # living-indoor is now near certain; living-garage and indoor-outdoor took
    # the same negative, but the garage route still needs its second edge.
    post = model.posterior()
    assert post[LIVING, INDOOR] > 0.99
    assert post[LIVING, GARAGE] == post[INDOOR, OUTDOOR]
    assert post[LIVING, INDOOR] * post[INDOOR, OUTDOOR] > post[LIVING, GARAGE] * post[GARAGE, OUTDOOR]
    assert model.plan("living_room", "outdoor") == [LIVING, INDOOR, OUTDOOR]


def test_reference_plan_goes_through_indoor():
    model = SemanticModel.from_reference()
    assert model.plan("living_room", "outdoor") == [LIVING, INDOOR, OUTDOOR]
    assert model.plan("kitchen", "dining_room") == [1, 2]


# --- model size, validation, I/O ---------------------------------------------


def test_reference_model_has_38_parameters():
    model = SemanticModel.from_reference()
    assert model.num_parameters() == 38
    assert (model.psi_obs0, model.psi_obs1) == (0.001, 0.15)


@pytest.mark.parametrize(
    "prior, match",
    [
        (np.full((8, 8), 0.5), r"\(8, 8\)"),
        (make_prior({(0, 1): 1.5}), "1.5"),
        (make_prior({(2, 5): 0.0}), "0.0"),
        (make_prior({}) + np.triu(np.full((N, N), 0.01), 1), "symmetric"),
    ],
)
def test_bad_priors_raise(prior, match):
    with pytest.raises(ValueError, match=match):
        SemanticModel(prior)


@pytest.mark.parametrize("psi", [1.0, -0.1, "0.1"])
def test_bad_noise_raises(psi):
    with pytest.raises(ValueError, match="psi_obs1"):
        SemanticModel(make_prior({}), psi_obs1=psi)


def test_prior_diagonal_is_ignored_and_prior_read_only():
    prior = make_prior({})
    np.fill_diagonal(prior, np.nan)
    model = SemanticModel(prior)
    np.testing.assert_array_equal(np.diag(model.prior), np.ones(N))
    with pytest.raises(ValueError):
        model.prior[0, 1] = 0.5


def test_json_round_trip(tmp_path):
    model = SemanticModel.from_reference()
    model.observe(0, 7, True)
    model.observe_bits([1, 1, 0, 0, 0, 0, 0, 0, 0])
    path = tmp_path / "model.json"
    model.to_json(path, include_counts=True)
    assert json.loads(path.read_text())["rooms"] == list(rooms.GRAPH_NODES)
    loaded = SemanticModel.from_json(path)
    np.testing.assert_array_equal(loaded.prior, model.prior)
    np.testing.assert_array_equal(loaded.n_pos, model.n_pos)
    np.testing.assert_array_equal(loaded.n_neg, model.n_neg)
    assert (loaded.psi_obs0, loaded.psi_obs1) == (model.psi_obs0, model.psi_obs1)
    model.to_json(path)  # overwrite, counts left out
    assert not SemanticModel.from_json(path).n_pos.any()
    assert [p.name for p in tmp_path.iterdir()] == ["model.json"]  # no temp files left


def test_malformed_json_raises_with_file_and_problem(tmp_path):
    path = tmp_path / "bad.json"
    path.write_text("{not json")
    with pytest.raises(ValueError, match="bad.json"):
        SemanticModel.from_json(path)
    with pytest.raises(ValueError, match="missing.json"):
        SemanticModel.from_json(tmp_path / "missing.json")
    path.write_text(json.dumps({"rooms": list(rooms.GRAPH_NODES), "psi_obs0": 0.001, "psi_obs1": 0.15}))
    with pytest.raises(ValueError, match=r"bad.json.*missing fields \['prior'\]"):
        SemanticModel.from_json(path)
    data = {"rooms": list(rooms.GRAPH_NODES), "prior": [[0.5] * 8] * 8, "psi_obs0": 0.001, "psi_obs1": 0.15}
    path.write_text(json.dumps(data))
    with pytest.raises(ValueError, match=r"bad.json.*\(8, 8\)"):
        SemanticModel.from_json(path)
    data.update(prior=make_prior({}).tolist(), rooms=list(rooms.ROOM_TYPES))
    path.write_text(json.dumps(data))
    with pytest.raises(ValueError, match="rooms"):
        SemanticModel.from_json(path)


# --- learning and comparing priors -------------------------------------------


def test_learn_prior_fraction_floor_and_symmetry():
    pos = np.zeros((N, N))
    trials = np.full((N, N), 10.0)
    pos[1, 2] = 7  # one triangle only: pooled with the other order
    pos[3, 4] = pos[4, 3] = 10  # always connected: capped
    trials[5, 6] = trials[6, 5] = 0  # never tried: floor
    prior = semantic.learn_prior(pos, trials, floor=1e-3)
    np.testing.assert_array_equal(prior, prior.T)
    assert prior[1, 2] == pytest.approx(7 / 20)
    assert prior[3, 4] == pytest.approx(1 - 1e-3)
    assert prior[5, 6] == prior[0, 1] == pytest.approx(1e-3)
    np.testing.assert_array_equal(np.diag(prior), np.ones(N))
    SemanticModel(prior)  # a valid prior


def test_learn_prior_scalar_trials_and_errors():
    pos = np.zeros((N, N))
    pos[0, 8] = pos[8, 0] = 30
    assert semantic.learn_prior(pos, 40)[0, 8] == pytest.approx(0.75)
    with pytest.raises(ValueError, match=r"\(8, 8\)"):
        semantic.learn_prior(np.zeros((8, 8)), 10)
    with pytest.raises(ValueError, match="exceeds"):
        semantic.learn_prior(pos, 20)
    with pytest.raises(ValueError, match="0.7"):
        semantic.learn_prior(pos, 40, floor=0.7)


def test_rank_correlation():
    ref = rooms.reference_prior()
    assert semantic.rank_correlation(ref, ref) == pytest.approx(1.0)
    assert semantic.rank_correlation(ref, 1 - ref) == pytest.approx(-1.0)
    with pytest.raises(ValueError, match="equal"):
        semantic.rank_correlation(ref, np.full((N, N), 0.5))


# --- plots -------------------------------------------------------------------


def test_plot_prior_writes_png(tmp_path):
    path = tmp_path / "prior.png"
    semantic.plot_prior(rooms.reference_prior(), path)
    assert path.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
    assert [p.name for p in tmp_path.iterdir()] == ["prior.png"]


def test_plot_belief_draws_on_axis():
    model = SemanticModel.from_reference()
    ax = matplotlib.figure.Figure().subplots()
    path = model.plan("living_room", "outdoor")
    assert semantic.plot_belief(model, ax, highlight_path=path) is ax
    red = [line for line in ax.lines if line.get_color() == "tab:red"]
    assert len(red) == len(path) - 1
