"""Credit for the goal choices of a policy-gradient round (``python -m leaps_mj.train goal --method reinforce``).

How much each goal the map-goal network chose is pushed up or down: by the episode's success, shared by all
of its choices, or by the geodesic progress each choice bought. The trainer
(:mod:`leaps_mj.learning.train_goal`) turns these advantages into its clipped policy-gradient loss.
"""

from __future__ import annotations

import numpy as np

from leaps_mj.world import rooms

#: How ``reinforce`` credits a goal choice (``GoalTrainConfig.credit``; see :func:`choice_advantages`).
CREDITS = ("episode", "progress")


def _node_means(values: np.ndarray, node: np.ndarray) -> np.ndarray:
    """The mean of ``values`` over the entries of each graph node (0 for a node with none): the baseline."""
    return np.array([values[node == n].mean() if (node == n).any() else 0.0 for n in range(len(rooms.GRAPH_NODES))])


def choice_advantages(samples: dict[str, np.ndarray], credit: str, gamma: float) -> np.ndarray:
    """Each sample's advantage for the policy gradient of ``reinforce`` (0 where no goal was chosen).

    ``episode``: the episode's success minus the mean success of the episodes of its node, shared by
    every choice of the episode (one bit for all of them). ``progress``: choice ``j`` of an episode
    drove from its step to the next choice's (the last one to the end); its return is
    ``sum_k gamma**k * progress[j + k]``, the geodesic metres towards the target walked under it and
    the choices after it, and the advantage is that return minus the mean return of its node's
    choices in the round, divided by the standard deviation of all of them. The distances come from
    the simulator: privileged, used only as the training signal.
    """
    if credit == "episode":
        node_of = np.zeros(len(samples["success"]), np.int64)
        node_of[samples["episode"]] = samples["node"]
        won = samples["success"].astype(np.float64)
        return (won - _node_means(won, node_of)[node_of])[samples["episode"]]
    chosen = np.flatnonzero(samples["choice"] >= 0)
    returns = np.zeros(len(samples["choice"]))
    for episode in np.unique(samples["episode"][chosen]):
        steps = chosen[samples["episode"][chosen] == episode]
        after = np.append(samples["distance"][steps[1:]], samples["final_distance"][episode])
        progress = samples["distance"][steps].astype(np.float64) - after
        running = 0.0
        for k in range(len(steps) - 1, -1, -1):
            running = progress[k] + gamma * running
            returns[steps[k]] = running
    node = samples["node"][chosen]
    advantage = np.zeros_like(returns)
    advantage[chosen] = returns[chosen] - _node_means(returns[chosen], node)[node]
    return advantage / max(float(advantage[chosen].std()) if len(chosen) else 0.0, 1e-6)
