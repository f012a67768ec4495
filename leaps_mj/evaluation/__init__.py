"""Evaluation: agents on fixed episodes, and what the paper reports of them.

The agent factory (:mod:`registry`), the harness behind
``python -m leaps_mj.evaluate`` (:mod:`harness`: resumable CSVs, tables with
intervals, paired tests, plots), the observation-noise grid search
(:mod:`tune_obs_noise`, an evaluation sweep) and the case-study figure
(:mod:`casestudy`). The top stage: it may import every other.
"""
