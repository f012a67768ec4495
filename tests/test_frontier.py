"""Tests for the frontier goals read off the agent's own map, and the frontier agent."""

import types

import numpy as np
import pytest

import leaps_mj
from leaps_mj.environment import expert, frontier, mapping
from leaps_mj.evaluation import registry
from leaps_mj.planning import agents
from leaps_mj.world import rooms

W, H = 40, 30
C = {name: i for i, name in enumerate(mapping.CHANNELS)}


def _room(target: str) -> tuple[types.SimpleNamespace, int, int]:
    """A driver stand-in at the grid's centre facing east, its semantic map showing only a walled square
    room of floor around it with a doorway in the east wall; the driver and the room's centre cell."""
    mapper = mapping.EgoMapper(target, W, H, semantic=True)
    seg = np.full((H, W), rooms.seg_class_index("empty"))
    mapper.update(seg, np.ones((H, W)), np.zeros(3))
    g, c, half = mapper.grid, mapping.GRID // 2, 12
    g[:] = 0
    g[C["floor"], c - half:c + half + 1, c - half:c + half + 1] = 1
    for side in (c - half - 1, c + half + 1):
        g[C["obstacle"], side, c - half - 1:c + half + 2] = 1
        g[C["obstacle"], c - half - 1:c + half + 2, side] = 1
    g[C["obstacle"], c - 2:c + 3, c + half + 1] = 0
    g[C["door"], c - 2:c + 3, c + half + 1] = 1
    mapper.blocked[:] = g[C["obstacle"]].astype(bool)
    g[C["visited"], c, c] = 1
    return types.SimpleNamespace(mapper=mapper, pose=np.array([0.125, 0.125, 0.0])), c, c


def _mark(driver, cls: str, rows, cols) -> None:
    """Marks a see-object of class ``cls`` as the mapper would: target channel, furniture, semantic channels."""
    g = driver.mapper.grid
    g[C["furniture"], rows, cols] = 1
    driver.mapper.blocked[rows, cols] = True
    if cls in rooms.SEE_OBJECTS.get(driver.mapper.target, ()):
        g[C["target"], rows, cols] = 1
    for k, room in enumerate(mapping.SEMANTIC):
        if cls in rooms.SEE_OBJECTS[room]:
            g[len(mapping.CHANNELS) + k, rows, cols] = 1


def _dining_room_table() -> tuple[types.SimpleNamespace, int, int]:
    """The room of :func:`_room`, looking for the dining room, with a table (a class the living room and
    the office share) in it."""
    driver, r, c = _room("dining_room")
    _mark(driver, "table", slice(r + 5, r + 7), slice(c - 6, c - 4))
    return driver, r, c


def _goal_rc(driver, goals) -> tuple[int, int]:
    row, col, _ = driver.mapper.cells(goals.goal[0], goals.goal[1])
    return int(row), int(col)


def test_with_nothing_of_the_target_mapped_the_goal_is_a_frontier_through_the_door():
    driver, r, c = _room("bedroom")
    goals = frontier.FrontierGoals()
    cell = goals.cell(driver)
    assert goals.kind == "frontier" and 0 <= cell < mapping.WINDOW ** 2
    row, col = _goal_rc(driver, goals)
    assert col == c + 12 + 1 and abs(row - r) <= 2  # the doorway: mapped floor next to unmapped space
    assert np.hypot(goals.goal[0] - driver.pose[0], goals.goal[1] - driver.pose[1]) >= frontier.MIN_FRONTIER


def test_a_mapped_target_object_is_approached_from_its_side_of_the_walls():
    driver, r, c = _room("bedroom")
    _mark(driver, "bed", slice(r + 6, r + 9), slice(c - 9, c - 5))
    goals = frontier.FrontierGoals()
    goals.cell(driver)
    assert goals.kind == "target" and goals.target_confirmed(driver.mapper)
    row, col = _goal_rc(driver, goals)
    bed = np.zeros((mapping.GRID, mapping.GRID), bool)
    bed[r + 6:r + 9, c - 9:c - 5] = True
    gap = np.min(np.hypot(*(np.argwhere(bed) - [row, col]).T)) * mapping.CELL
    assert gap <= 0.5  # right next to the bed, not just within reach


def test_a_shared_object_beside_another_rooms_own_is_no_target():
    driver, r, c = _dining_room_table()
    goals = frontier.FrontierGoals()
    goals.cell(driver)
    assert goals.kind == "target" and not goals.target_confirmed(driver.mapper)  # a table alone: a guess
    _mark(driver, "sofa", slice(r + 8, r + 10), slice(c - 6, c - 3))  # beside a sofa
    goals.reset()
    goals.cell(driver)
    assert goals.kind == "frontier"


def test_a_target_goal_stood_at_without_success_is_rejected():
    driver, _, _ = _dining_room_table()
    goals = frontier.FrontierGoals()
    goals.cell(driver)
    first = goals.goal.copy()
    driver.pose = np.array([first[0], first[1], 0.0])  # arrived; the run goes on, so the see test failed
    kinds = []
    for _ in range(frontier.TARGET_PATIENCE + 3):
        goals.cell(driver)
        kinds.append(goals.kind)
    assert kinds[0] == "target" and kinds[-1] == "frontier"
    assert not goals.target_confirmed(driver.mapper) and not goals._targets(driver.mapper).any()


@pytest.fixture(scope="module")
def env(tiny_dataset):
    e = leaps_mj.load(str(tiny_dataset), "train", seed=0, width=W, height=H, horizon=60, max_start_doors=1)
    yield e
    e.close()


def test_the_frontier_agent_scans_then_walks_and_reaches_rooms(env):
    agent = registry.make_agent("frontier", env, seed=0)
    successes, moves = 0, 0
    for _ in range(4):
        ts = env.reset()
        agent.reset(env.episode.target)
        actions = []
        while not ts.last():
            actions.append(agent.step(ts))
            scanning = len(actions) <= agents.SCAN_TURNS and all(a == expert.LEFT for a in actions)
            # A full look around first, cut short only once objects of the target's own classes are in sight.
            assert scanning or ts.last() or agent.goals.target_confirmed(agent.driver.mapper) or \
                actions[:agents.SCAN_TURNS] == [expert.LEFT] * agents.SCAN_TURNS
            ts = env.step(actions[-1])
        successes += env.task.success
        moves += sum(a in (expert.FORWARD, expert.SMALL_FORWARD) for a in actions)
    assert successes >= 2 and moves > 0
