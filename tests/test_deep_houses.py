"""Tests for the deep houses of roomnav-v2: floor plans, doors, plan lengths and episode coverage."""

import collections

import numpy as np
import pytest

import leaps_mj
from leaps_mj.environment import episodes
from leaps_mj.world import dataset, floorplan, generator, houses, navgrid, rooms

N_HOUSES = 60


@pytest.fixture(scope="module")
def deep_set():
    """The first houses of the canonical test split, generated afresh."""
    return [generator.generate(dataset.house_seed(0, "test", i), dataset.house_id("test", i)) for i in range(N_HOUSES)]


def _programme(seed):
    return generator.sample_programme(np.random.default_rng(seed))


def test_floor_plan_is_deterministic_and_rooms_do_not_overlap():
    for seed in range(40):
        prog = _programme(seed)
        a = floorplan.floor_plan(np.random.default_rng(seed), prog)
        assert a == floorplan.floor_plan(np.random.default_rng(seed), prog)
        rects = [r for _, r in a.rooms]
        for i, (x0, y0, x1, y1) in enumerate(rects):
            assert x1 - x0 > 1.0 and y1 - y0 > 1.0, (seed, a.rooms[i])
            for bx0, by0, bx1, by1 in rects[i + 1:]:
                overlap = min(x1, bx1) - max(x0, bx0) > 1e-6 and min(y1, by1) - max(y0, by0) > 1e-6
                assert not overlap, (seed, a.rooms[i])
        assert a.rooms[a.hallways[0]][0] == "hallway"
        assert len(a.hallways) == (2 if a.shape == "L" else 1)


def test_l_plans_join_their_hallways_and_hold_a_bedroom_wing(deep_set):
    l_houses = [h for h in deep_set if sum(r.name.startswith("hallway") for r in h.rooms) == 2]
    assert len(l_houses) >= N_HOUSES // 4
    for h in l_houses:
        halls = [r.id for r in h.rooms if r.name.startswith("hallway")]
        assert tuple(sorted(halls)) in h.connectivity(), h.id
        second_wing = {b if a == halls[1] else a for a, b in h.connectivity() if halls[1] in (a, b)}
        assert any(h.rooms[i].type in ("bedroom", "bathroom") for i in second_wing), h.id


def test_garages_are_entered_from_inside_and_not_always_from_the_yard(deep_set):
    garage_houses = [h for h in deep_set if "garage" in h.room_types]
    assert garage_houses
    through_mudroom = yard_door = 0
    for h in garage_houses:
        g = h.room_types.index("garage")
        neighbours = {h.rooms[b if a == g else a] for a, b in h.connectivity() if g in (a, b)}
        through_mudroom += any(r.name.startswith("mudroom") for r in neighbours)
        yard_door += any(r.type == "outdoor" for r in neighbours)
        assert neighbours, h.id
    assert through_mudroom >= 1
    assert yard_door < len(garage_houses)


def test_every_room_reachable_in_deep_houses(deep_set):
    for h in deep_set:
        if h.diameter() >= 5:
            navgrid.NavGrid(h).check_reachable()


def test_plan_lengths_and_diameter(deep_set):
    h = max(deep_set, key=houses.House.diameter)
    assert h.diameter() >= 5
    for target in set(h.room_types) & set(rooms.ROOM_TYPES):
        hops = h.plan_lengths(target)
        for r in h.rooms:
            assert (hops[r.id] == 0) == (r.type == target)
        # One door changes the hop count by at most one.
        for a, b in h.connectivity():
            assert abs(hops[a] - hops[b]) <= 1
    assert h.plan_lengths("garage") == {} or "garage" in h.room_types
    with pytest.raises(ValueError, match="unknown room type 'attic'"):
        h.plan_lengths("attic")


def _coverage(split):
    by_length = collections.defaultdict(list)
    for spec in episodes.load_split(dataset.CANONICAL, split):
        by_length[spec.plan_length].append(spec)
    return {k: (len(v), len({s.house for s in v}), len({s.target for s in v})) for k, v in by_length.items()}


def test_canonical_test_episodes_cover_long_plans():
    cov = _coverage("test")
    assert sorted(cov) == [1, 2, 3, 4, 5]
    for length in (4, 5):
        n, n_houses, n_targets = cov[length]
        assert n == 500 and n_houses >= 10 and n_targets >= 5, (length, cov[length])


def test_canonical_valid_episodes_cover_every_plan_length():
    cov = _coverage("valid")
    assert sorted(cov) == [1, 2, 3, 4, 5]
    for length, (n, n_houses, _) in cov.items():
        assert n == 100 and n_houses >= 3, (length, cov[length])


def test_canonical_episode_files_match_a_fresh_draw(tmp_path):
    """The committed episodes are what tools/make_episodes.py draws (valid split, seed 0)."""
    eps, _ = episodes.generate(dataset.CANONICAL, "valid", per_length=100, seed=0)
    episodes.write(tmp_path / "valid.jsonl", eps)
    committed = episodes.episodes_path(dataset.CANONICAL, "valid")
    assert (tmp_path / "valid.jsonl").read_bytes() == committed.read_bytes()


def test_the_committed_large_hop_set_matches_a_fresh_draw(tmp_path):
    """``python tools/make_episodes.py --hops --large`` draws the committed large hop set (valid split)."""
    quotas, seed = episodes.HOP_SETS["hops_large"]
    eps, _ = episodes.generate_hops(dataset.CANONICAL, "valid", per_node=quotas["valid"], seed=seed)
    episodes.write(tmp_path / "large.jsonl", eps)
    committed = episodes.episodes_path(dataset.CANONICAL, "valid", "hops_large")
    assert (tmp_path / "large.jsonl").read_bytes() == committed.read_bytes()


def test_roomnav_v1_stays_loadable():
    assert dataset.CANONICAL == "roomnav-v2"
    assert dataset.verify("roomnav-v1") == []
    env = leaps_mj.load("roomnav-v1", split="test", seed=0)
    try:
        spec = episodes.load_split("roomnav-v1", "test")[0]
        ts = env.reset_to(spec)
        assert ts.observation["segmentation"].shape == (90, 120)
        assert env.episode.house.startswith("test_")
    finally:
        env.close()
