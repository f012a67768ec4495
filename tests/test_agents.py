"""Tests for the agents: LEAPS replanning on synthetic steps, the local expert and oracle in a real house."""

import dm_env
import numpy as np
import pytest

import leaps_mj
from leaps_mj.environment import episodes
from leaps_mj.evaluation import registry
from leaps_mj.planning import agents, semantic
from leaps_mj.world import rooms

N = semantic.NUM_NODES


def make_prior(edges, background=0.01):
    """9x9 symmetric prior: `background` everywhere, `edges` {(a, b): p} on top (names)."""
    prior = np.full((N, N), background)
    for (a, b), p in edges.items():
        i, j = rooms.room_index(a), rooms.room_index(b)
        prior[i, j] = prior[j, i] = p
    np.fill_diagonal(prior, 1.0)
    return prior


#: Kitchen to outdoor: via the garage (0.6 * 0.8 = 0.48) beats via the living room (0.5 * 0.6 = 0.30).
GARAGE_FIRST = make_prior({("kitchen", "garage"): 0.6, ("garage", "outdoor"): 0.8,
                           ("kitchen", "living_room"): 0.5, ("living_room", "outdoor"): 0.6})


def timestep(*where, target="outdoor"):
    """A mid-episode time step whose semantic bits are on for the rooms in ``where``."""
    bits = np.zeros(rooms.NUM_ROOM_TYPES, dtype=np.uint8)
    for name in where:
        bits[rooms.room_index(name)] = 1
    onehot = np.zeros(rooms.NUM_ROOM_TYPES, dtype=np.uint8)
    onehot[rooms.room_index(target)] = 1
    return dm_env.transition(0.0, {"semantic": bits, "target": onehot})


class FakeSubPolicy:
    """Records which sub-targets it was reset for and how many actions it gave."""

    def __init__(self):
        self.resets = []
        self.acts = 0

    def reset(self, target):
        self.resets.append(target)

    def act(self, timestep):
        self.acts += 1
        return 8


def run(agent, steps):
    """Feeds (count, rooms) runs of synthetic time steps to an agent."""
    for count, where in steps:
        for _ in range(count):
            assert agent.step(timestep(*where, target=agent.target)) == 8


@pytest.mark.parametrize("rule", agents.RULES)
def test_failed_subtarget_reroutes_release_rule(rule):
    # Outdoor via the garage; the garage run fails while the agent stays in the kitchen.
    sub = FakeSubPolicy()
    agent = agents.LeapsAgent(sub, semantic.SemanticModel(GARAGE_FIRST), replan_every=30, rule=rule)
    agent.reset("outdoor")
    run(agent, [(1, ["kitchen"])])
    assert agent.info()["plan"] == ["kitchen", "garage", "outdoor"]
    assert agent.info()["subtarget"] == "garage"
    run(agent, [(30, ["kitchen"])])
    if rule == "release":
        # One negative for kitchen-garage: 0.6 -> 0.18, so via garage 0.15 < via living room 0.30.
        assert agent.info()["plan"] == ["kitchen", "living_room", "outdoor"]
        run(agent, [(3, ["living_room"]), (2, ["outdoor"])])
        assert sub.resets == ["garage", "living_room", "outdoor"]
        assert [h.reason for h in agent.history] == ["start", "window", "reached"]
        assert agent.history[-1].plan == ("living_room", "outdoor")
        assert agent.info()["subtarget"] == "outdoor"
    else:
        # The paper's rule penalises every edge out of the kitchen alike: the plan stays.
        assert agent.info()["plan"] == ["kitchen", "garage", "outdoor"]
        assert sub.resets == ["garage"]
    assert sub.acts == 1 + 30 + (5 if rule == "release" else 0)


def test_paper_rule_reroutes_when_the_failed_run_reveals_a_connection():
    # During the failed garage run the agent passes through the living room: kitchen-living is
    # observed connected (-> 0.999) while kitchen-garage and living-outdoor take a negative.
    sub = FakeSubPolicy()
    agent = agents.LeapsAgent(sub, semantic.SemanticModel(GARAGE_FIRST), replan_every=30, rule="paper")
    agent.reset("outdoor")
    run(agent, [(10, ["kitchen"]), (10, ["living_room"]), (11, ["kitchen"])])
    assert [h.reason for h in agent.history] == ["start", "window"]
    assert agent.history[1].plan == ("kitchen", "living_room", "outdoor")
    counts = agent.model.n_pos.sum(), agent.model.n_neg.sum()
    run(agent, [(1, ["kitchen", "living_room"]), (1, ["living_room"])])
    assert agent.history[-1].reason == "reached"
    assert (agent.model.n_pos.sum(), agent.model.n_neg.sum()) == counts  # only full windows observe
    assert agent.info()["plan"] == ["living_room", "outdoor"]  # planned from the doorway's two rooms
    run(agent, [(1, ["outdoor"])])
    assert sub.resets == ["garage", "living_room", "outdoor"]
    post = agent.info()["belief"]
    k, g, lv = (rooms.room_index(r) for r in ("kitchen", "garage", "living_room"))
    assert post[k, lv] > 0.99 and post[k, g] < 0.6


def test_replans_every_n_steps_and_on_entering_the_target():
    sub = FakeSubPolicy()
    agent = agents.LeapsAgent(sub, semantic.SemanticModel(GARAGE_FIRST), replan_every=5, rule="paper")
    agent.reset("outdoor")
    run(agent, [(12, ["kitchen"])])
    assert [h.step for h in agent.history] == [0, 5, 10]
    # The target is entered before the sub-target: run the target's own sub-policy.
    run(agent, [(1, ["outdoor"])])
    assert agent.history[-1].reason == "target"
    assert agent.info() == {"subtarget": "outdoor", "plan": ["outdoor"], "belief": agent.history[-1].belief}
    assert sub.resets[-1] == "outdoor"


def test_untyped_indoor_space_is_the_indoor_node_and_reset_forgets():
    model = semantic.SemanticModel(make_prior({("indoor", "bedroom"): 0.9}))
    agent = agents.LeapsAgent(FakeSubPolicy(), model, rule="paper")
    agent.reset("bedroom")
    run(agent, [(31, [])])
    assert agent.history[0].here == ("indoor",)
    assert agent.history[0].plan == ("indoor", "bedroom")
    assert model.n_neg.sum() > 0
    agent.reset("bedroom")
    assert model.n_neg.sum() == 0 and agent.history == [] and agent.info()["plan"] == []


def test_leaps_rejects_bad_input():
    model = semantic.SemanticModel(GARAGE_FIRST)
    with pytest.raises(ValueError, match="rule"):
        agents.LeapsAgent(FakeSubPolicy(), model, rule="magic")
    with pytest.raises(ValueError, match="replan_every"):
        agents.LeapsAgent(FakeSubPolicy(), model, replan_every=0)
    agent = agents.LeapsAgent(FakeSubPolicy(), model)
    with pytest.raises(ValueError, match="before reset"):
        agent.step(timestep("kitchen"))
    with pytest.raises(ValueError, match="unknown target"):
        agent.reset("indoor")
    agent.reset("garage")
    with pytest.raises(ValueError, match="does not match"):
        agent.step(timestep("kitchen", target="outdoor"))


def test_random_agent_is_seeded():
    a, b = agents.RandomAgent(3), agents.RandomAgent(3)
    a.reset("kitchen")
    b.reset("kitchen")
    acts = [a.step(None) for _ in range(50)]
    assert acts == [b.step(None) for _ in range(50)]
    assert set(acts) <= set(range(rooms.NUM_ACTIONS)) and len(set(acts)) > 3
    assert a.info() == {"subtarget": None, "plan": [], "belief": None}


def test_make_agent_checks_names_and_options():
    with pytest.raises(ValueError, match="unknown agent"):
        registry.make_agent("greedy", None)
    with pytest.raises(ValueError, match="takes no options"):
        registry.make_agent("random", None, rule="paper")
    with pytest.raises(ValueError, match="no prior file"):
        agents.load_model("/nonexistent/prior.json")
    sub = FakeSubPolicy()
    leaps = registry.make_agent("leaps", None, subpolicy=sub, prior="reference", rule="release", replan_every=7)
    assert isinstance(leaps, agents.LeapsAgent) and leaps.subpolicy is sub
    assert (leaps.rule, leaps.replan_every) == ("release", 7)
    assert isinstance(sub, agents.SubPolicy) and isinstance(leaps, agents.Agent)
    with pytest.raises(ValueError, match="load_augmented"):
        registry.make_agent("aug", None)
    aug = registry.make_agent("aug", None, subpolicy=sub)
    assert aug.name == "aug" and aug.subpolicy is sub


@pytest.fixture(scope="module")
def env(tiny_dataset):
    e = leaps_mj.load(str(tiny_dataset), "test", reward="sparse", horizon=300)
    yield e
    e.close()


def _episode(tiny_dataset, plan_length):
    return next(s for s in episodes.load_split(str(tiny_dataset), "test") if s.plan_length == plan_length)


def _run(env, agent, spec):
    ts = env.reset_to(spec)
    agent.reset(spec.target)
    while not ts.last():
        ts = env.step(agent.step(ts))
    return env.task.success


@pytest.mark.parametrize("name", ["pure", "oracle", "oracle-scan"])
def test_local_expert_and_oracle_reach_a_near_target(env, tiny_dataset, name):
    assert _run(env, registry.make_agent(name, env, seed=1), _episode(tiny_dataset, 1))


def test_local_expert_explores_far_from_the_target(env, tiny_dataset):
    spec = next(s for s in episodes.load_split(str(tiny_dataset), "test") if s.plan_length >= 2)
    policy = agents.LocalExpertPolicy(env, seed=0, explore_radius=2.5)
    ts = env.reset_to(spec)
    policy.reset(spec.target)
    goals = []
    for _ in range(60):
        ts = env.step(policy.act(ts))
        assert policy.mode == "explore"
        goals.append(tuple(policy.goal))
    assert len(set(goals)) > 1  # arrived, or gave up, and drew the next goal
    distance = np.hypot(*(np.array(goals[0]) - np.array(spec.start[:2])))
    assert 1.0 - 0.2 <= distance <= 2.5 + 0.2
