"""Every evaluated agent by name: the planning agents and the learned baselines.

One factory above both stages, so that :mod:`leaps_mj.planning` need not know
the networks of :mod:`leaps_mj.learning` and the harness, case study and
examples build agents the same way. The baselines (and torch) are imported only
when one is asked for: torch is an optional dependency.
"""

from __future__ import annotations

from leaps_mj.planning import agents

#: Agent names accepted by :func:`make_agent`.
AGENT_NAMES = ("random", "pure", "leaps", "oracle", "oracle-scan", "oracle-look", "oracle-map", "oracle-map-observable",
               "oracle-map-furniture", "oracle-map-sensed", "oracle-map-gated", "oracle-map-potential", "observable",
               "frontier", "controller", "aug")


def make_agent(name: str, env, subpolicy: agents.SubPolicy | None = None, seed: int = 0, **kwargs) -> agents.Agent:
    """Builds an agent by name.

    Args:
      name: one of :data:`AGENT_NAMES`.
      env: the environment (for agents and sub-policies reading privileged state).
      subpolicy: the sub-policy of "pure", "leaps" and "controller" (any
        :class:`leaps_mj.planning.agents.SubPolicy`, e.g. the learned ones; default a
        :class:`leaps_mj.planning.agents.LocalExpertPolicy`), or μ_s for "aug" (required:
        ``leaps_mj.learning.policy_folder.load_augmented(policy_dir)``).
      seed: seed of the agent's (and default sub-policy's) random draws.
      **kwargs: for "leaps": ``model`` (a SemanticModel) or ``prior`` (see
        :func:`leaps_mj.planning.agents.load_model`), ``replan_every``, ``rule``; for "controller":
        ``controller``, the checkpoint's path (default: the shipped one, trained over the shipped μ(θ)).

    Raises:
      ValueError: for an unknown name or keyword arguments the agent does not take.
    """
    if name not in AGENT_NAMES:
        raise ValueError(f"unknown agent {name!r}; expected one of {list(AGENT_NAMES)}")
    allowed = {"leaps": {"model", "prior", "replan_every", "rule"}, "controller": {"controller"}}.get(name, set())
    if set(kwargs) - allowed:
        raise ValueError(f"agent {name!r} takes no options {sorted(set(kwargs) - allowed)}; "
                         f"expected a subset of {sorted(allowed)}")
    if name == "random":
        return agents.RandomAgent(seed)
    if name == "oracle":
        return agents.OracleAgent(env, seed)
    if name == "oracle-scan":
        return agents.ScanningOracleAgent(env, seed)
    if name == "oracle-look":
        return agents.LookingOracleAgent(env, seed)
    if name == "oracle-map":
        return agents.MapOracleAgent(env, seed)
    if name == "oracle-map-observable":
        return agents.ObservableMapOracleAgent(env, seed)
    if name == "oracle-map-furniture":
        return agents.FurnitureMapOracleAgent(env, seed)
    if name == "oracle-map-sensed":
        return agents.SensedMapOracleAgent(env, seed)
    if name == "oracle-map-gated":
        return agents.GatedMapOracleAgent(env, seed)
    if name == "oracle-map-potential":
        return agents.PotentialMapOracleAgent(env, seed)
    if name == "observable":
        return agents.ObservableAgent(env, seed)
    if name == "frontier":
        return agents.FrontierAgent(seed)
    if name == "aug":
        from leaps_mj.learning import baselines

        if subpolicy is None:
            raise ValueError("agent 'aug' needs its semantic-augmented policy μ_s as subpolicy "
                             "(leaps_mj.learning.policy_folder.load_augmented(policy_dir))")
        return baselines.AugmentedPolicyAgent(subpolicy)
    sub = subpolicy if subpolicy is not None else agents.LocalExpertPolicy(env, seed)
    if name == "pure":
        return agents.PureAgent(sub)
    if name == "controller":
        from leaps_mj.learning import baselines

        return baselines.ControllerAgent.from_checkpoint(sub, kwargs.get("controller", baselines.DEFAULT_CONTROLLER),
                                                         seed=seed)
    if "model" in kwargs and "prior" in kwargs:
        raise ValueError("give the LEAPS agent either model or prior, not both")
    model = kwargs.pop("model", None) or agents.load_model(kwargs.pop("prior", agents.DEFAULT_PRIOR))
    return agents.LeapsAgent(sub, model, **kwargs)
