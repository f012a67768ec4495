"""The learned sub-policies of a folder, whichever kind its checkpoints are.

Evaluation (``--policy-dir``) and the controller's trainer both run "the
learned sub-policies in this folder": per-target CNN+LSTM networks μ(θ)
(``<node>.pt``, ``shared.pt``) or the map-goal network (``goal.pt``). This
module decides which from the files, so that both load a folder the same way.
A folder is given as a path or as the name of a shipped one (:data:`SHIPPED`).
"""

from __future__ import annotations

import os
import pathlib

from leaps_mj.learning import baselines, goal_policy, policies
from leaps_mj.world import rooms

#: File name of the controller trained over a folder's sub-policies.
CONTROLLER = "controller.pt"
#: Sub-folder of the semantic-augmented policy μ_s trained with a folder's recipe.
AUGMENTED = "aug"
#: The shipped sub-policy folders by name: the per-target CNN+LSTM networks μ(θ) and the map-goal network.
SHIPPED = {"cpu": policies.DEFAULT_DIR, "goal_cpu": goal_policy.DEFAULT_DIR}
#: The shipped folder that evaluation drives by default: the map-goal sub-policy, the best on the hop benchmark.
DEFAULT = "goal_cpu"


def resolve(policy_dir: str | os.PathLike | None) -> pathlib.Path | None:
    """The folder ``policy_dir`` names: None (the shipped μ(θ)) stays None; a name of :data:`SHIPPED` that is
    no existing path is that shipped folder; anything else is a path."""
    if policy_dir is None:
        return None
    if not pathlib.Path(policy_dir).exists() and str(policy_dir) in SHIPPED:
        return SHIPPED[str(policy_dir)]
    return pathlib.Path(policy_dir)


def load(policy_dir: str | os.PathLike | None, temperature: float = 1.0, seed: int = 0):
    """The learned sub-policies: the shipped μ(θ), or those in ``policy_dir`` (every ``<node>.pt``
    checkpoint, and a ``shared.pt`` network for the nodes without one), sampling at ``temperature``;
    or, where ``policy_dir`` holds a ``goal.pt``, the map-goal sub-policy
    (:class:`leaps_mj.learning.goal_policy.GoalSubPolicy`, deterministic) for every node.

    Raises:
      ValueError: if the folder holds no checkpoint of a graph node, or one is unreadable; for a
        temperature other than 1 with the map-goal sub-policy, which does not sample.
    """
    policy_dir = resolve(policy_dir)
    if policy_dir is None:
        return policies.load_default(seed=seed, temperature=temperature)
    if (policy_dir / goal_policy.GOAL).is_file():
        if temperature != 1.0:
            raise ValueError(f"temperature {temperature!r}: the map-goal sub-policy in {str(policy_dir)!r} does not "
                             f"sample its actions; expected 1")
        return goal_policy.GoalSubPolicy(policy_dir, seed=seed)
    targets = policies.folder_targets(policy_dir)
    if not targets:
        raise ValueError(f"policy folder {str(policy_dir)!r} holds no sub-policy checkpoint <node>.pt or shared.pt "
                         f"for any of {list(rooms.GRAPH_NODES)}")
    return policies.LearnedSubPolicy(policy_dir, targets, seed=seed, temperature=temperature)


def controller_path(policy_dir: str | os.PathLike | None) -> pathlib.Path:
    """The controller to drive a folder's sub-policies: its own ``controller.pt`` where it has one, else the
    shipped controller (:data:`leaps_mj.learning.baselines.DEFAULT_CONTROLLER`, trained over the shipped μ(θ))."""
    policy_dir = resolve(policy_dir)
    if policy_dir is not None and (policy_dir / CONTROLLER).is_file():
        return policy_dir / CONTROLLER
    return baselines.DEFAULT_CONTROLLER


def load_augmented(policy_dir: str | os.PathLike | None, seed: int = 0):
    """The semantic-augmented policy μ_s of the ``aug`` baseline for a folder's sub-policies: the map-goal
    network with room-type bits in ``<policy_dir>/aug/`` where there is one, else the shipped per-target μ_s
    (:func:`leaps_mj.learning.policies.load_augmented`).

    Raises:
      ValueError: if ``<policy_dir>/aug/goal.pt`` is a network that does not read the room-type bits.
    """
    policy_dir = resolve(policy_dir)
    folder = policy_dir / AUGMENTED if policy_dir is not None else None
    if folder is None or not (folder / goal_policy.GOAL).is_file():
        return policies.load_augmented(seed=seed)
    augmented = goal_policy.GoalSubPolicy(folder, seed=seed)
    if not augmented.net.config.room_bits:
        raise ValueError(f"{folder / goal_policy.GOAL} does not read the room-type bits, so it is no μ_s; "
                         f"train it with `python -m leaps_mj.train goal --room-bits true`")
    return augmented
