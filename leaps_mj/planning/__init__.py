"""Planning: the semantic model and the agents that plan on it.

The Bayesian room-connectivity model with its prior, noisy observations,
posterior and max-probability planning (:mod:`semantic`), and the agents
(:mod:`agents`: random, pure sub-policy, LEAPS, the oracle, the local-expert
sub-policy). Agents drive sub-policies through a small protocol, so nothing
here needs torch. Imports :mod:`leaps_mj.environment` and :mod:`leaps_mj.world`.
"""
