"""Statistics of evaluation results: success within a horizon, Wilson intervals, paired tests.

Every agent runs the same fixed episodes with the same per-episode seeds, so
two agents are compared episode by episode (:func:`paired_test`), not only by
their success rates' intervals.
"""

from __future__ import annotations

import math

import numpy as np
import scipy.stats


def success_at(rows: list[dict], horizon: int) -> np.ndarray:
    """Per-episode success within ``horizon`` steps, derived from the success steps."""
    return np.array([r["success_step"] is not None and r["success_step"] <= horizon for r in rows], dtype=bool)


def wilson(successes: int, n: int, confidence: float = 0.95) -> tuple[float, float]:
    """Wilson score interval of a binomial proportion ((nan, nan) when n = 0)."""
    if n == 0:
        return math.nan, math.nan
    ci = scipy.stats.binomtest(int(successes), int(n)).proportion_ci(confidence, method="wilson")
    return float(ci.low), float(ci.high)


def paired_test(a: np.ndarray, b: np.ndarray) -> dict:
    """Exact McNemar (sign) test of two agents' successes on the same episodes.

    Only the discordant episodes count: under "no difference" each is as
    likely to be won by either agent, so their split is Binomial(n, 1/2).

    Returns:
      ``{"n", "a", "b", "a_only", "b_only", "p"}``: episodes, successes of each,
      episodes only one of them solved, and the two-sided p-value (1 without discordant episodes).

    Raises:
      ValueError: if the arrays differ in shape.
    """
    a, b = np.asarray(a, dtype=bool), np.asarray(b, dtype=bool)
    if a.shape != b.shape:
        raise ValueError(f"paired successes of shapes {a.shape} and {b.shape}: expected the same episodes")
    a_only, b_only = int((a & ~b).sum()), int((b & ~a).sum())
    p = scipy.stats.binomtest(a_only, a_only + b_only, 0.5).pvalue if a_only + b_only else 1.0
    return {"n": int(a.size), "a": int(a.sum()), "b": int(b.sum()), "a_only": a_only, "b_only": b_only,
            "p": float(p)}


def rate(mask: np.ndarray) -> dict:
    """``{"n", "successes", "rate", "low", "high"}`` of a boolean array."""
    n, k = int(mask.size), int(mask.sum())
    low, high = wilson(k, n)
    return {"n": n, "successes": k, "rate": k / n if n else math.nan, "low": low, "high": high}


def paired_comparisons(table: dict[str, list[dict]], horizons, leaps, baselines) -> dict:
    """Each of the ``leaps`` agents against each of the ``baselines`` on their common episodes.

    Success rates with overlapping intervals can still differ: every agent ran
    the same episodes with the same seeds, so the exact McNemar test on the
    episodes only one of the two solved is the sharper comparison.

    Returns:
      ``{leaps: {baseline: {str(H): {"all": test, "plan_length": {L: test}}}}}``
      with the dicts of :func:`paired_test` (``a`` = LEAPS, ``b`` = the baseline).
    """
    out = {}
    for a in leaps:
        for b in baselines:
            rows_a = {r["episode"]: r for r in table[a]}
            rows_b = {r["episode"]: r for r in table[b]}
            common = sorted(set(rows_a) & set(rows_b))
            if not common:
                continue
            ra, rb = [rows_a[e] for e in common], [rows_b[e] for e in common]
            lengths = np.array([r["plan_length"] or 0 for r in ra])   # as the harness's summary counts them
            per_h = {}
            for h in horizons:
                sa, sb = success_at(ra, h), success_at(rb, h)
                per_h[str(h)] = {"all": paired_test(sa, sb), "plan_length": {
                    int(L): paired_test(sa[lengths == L], sb[lengths == L]) for L in np.unique(lengths)}}
            out.setdefault(a, {})[b] = per_h
    return out
