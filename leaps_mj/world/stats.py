"""Semantic statistics of a set of houses, compared with real homes.

The reference is the original LEAPS release (``rooms.reference()``): the
fraction of its SUNCG training houses that contain each room type, and the
room-connectivity prior ψ_prior it learned on them. Two caveats when reading
the comparison:

* Our adjacency frequency of a type pair is *structural*: among the houses that
  contain both types, the fraction in which a door joins a room of one type to
  a room of the other. The reference prior is *behavioural*: the probability
  that a random walk of at most 300 steps started in one room reaches the other.
  The two agree in ranking (doors make short walks succeed) but not in
  absolute value, so the headline number is a Spearman rank correlation.
* The untyped ``indoor`` node is every room of no target type (the hallway,
  closets, storage), as in the release.
"""

from __future__ import annotations

import dataclasses
import itertools
from collections.abc import Iterable

import numpy as np
import scipy.stats

from leaps_mj.world import houses, rooms

#: The 36 unordered pairs of distinct graph nodes, in GRAPH_NODES order.
PAIRS = tuple(itertools.combinations(rooms.GRAPH_NODES, 2))


@dataclasses.dataclass(frozen=True)
class HouseStats:
    """Statistics of a set of houses.

    Attributes:
      n_houses: number of houses.
      type_frequency: room type (and ``indoor``) → fraction of houses with one.
      rooms_per_house: (mean, min, max) number of indoor rooms.
      typed_per_house: mean number of distinct target room types per house
        (outdoor included, as in the reference's ``mean_room_types_per_house``).
      adjacency: (type a, type b) → fraction of the houses containing both
        types in which a door joins them; NaN if no house contains both.
      cooccurrence: (type a, type b) → number of houses containing both.
      rooms_distribution: number of indoor rooms → number of houses.
      diameter_distribution: house diameter (the longest optimal plan in the
        house, :meth:`leaps_mj.world.houses.House.diameter`) → number of
        houses; it bounds the plan lengths a house can offer episodes.
    """

    n_houses: int
    type_frequency: dict[str, float]
    rooms_per_house: tuple[float, int, int]
    typed_per_house: float
    adjacency: dict[tuple[str, str], float]
    cooccurrence: dict[tuple[str, str], int]
    rooms_distribution: dict[int, int]
    diameter_distribution: dict[int, int]

    def adjacency_matrix(self) -> np.ndarray:
        """The adjacency frequencies as a symmetric 9x9 matrix (diagonal 1)."""
        n = len(rooms.GRAPH_NODES)
        m = np.eye(n)
        for (a, b), v in self.adjacency.items():
            i, j = rooms.room_index(a), rooms.room_index(b)
            m[i, j] = m[j, i] = v
        return m


def _pair(a: str, b: str) -> tuple[str, str]:
    ia, ib = rooms.room_index(a), rooms.room_index(b)
    return (a, b) if ia < ib else (b, a)


def compute(house_list: Iterable[houses.House]) -> HouseStats:
    """Statistics of ``house_list``.

    Raises:
      ValueError: if the list is empty.
    """
    has = {t: 0 for t in rooms.GRAPH_NODES}
    both = {p: 0 for p in PAIRS}
    joined = {p: 0 for p in PAIRS}
    n_rooms, n_types, diameters = [], [], []
    n = 0
    for h in house_list:
        n += 1
        types = set(h.room_types)
        for t in types:
            has[t] += 1
        n_rooms.append(len(h.indoor_rooms))
        n_types.append(len(types - {rooms.INDOOR}))
        diameters.append(h.diameter())
        for a, b in PAIRS:
            if a in types and b in types:
                both[(a, b)] += 1
        for a, b in h.type_adjacency():
            joined[_pair(a, b)] += 1
    if n == 0:
        raise ValueError("no houses to compute statistics on")
    return HouseStats(
        n_houses=n,
        type_frequency={t: has[t] / n for t in rooms.GRAPH_NODES},
        rooms_per_house=(float(np.mean(n_rooms)), int(np.min(n_rooms)), int(np.max(n_rooms))),
        typed_per_house=float(np.mean(n_types)),
        adjacency={p: (joined[p] / both[p] if both[p] else float("nan")) for p in PAIRS},
        cooccurrence=dict(both),
        rooms_distribution=_histogram(n_rooms),
        diameter_distribution=_histogram(diameters),
    )


def _histogram(values: list[int]) -> dict[int, int]:
    """value → count, sorted by value."""
    return {int(v): int(c) for v, c in zip(*np.unique(values, return_counts=True))}


def reference_adjacency() -> dict[tuple[str, str], float]:
    """The reference prior ψ_prior over the 36 pairs."""
    prior = rooms.reference_prior()
    return {(a, b): float(prior[rooms.room_index(a), rooms.room_index(b)]) for a, b in PAIRS}


def reference_frequency(split: str = "train_200") -> dict[str, float]:
    """Fraction of the reference's houses containing each target room type."""
    ref = rooms.reference()["room_type_frequency_in_houses"][split]
    return {t: float(ref[t]) for t in rooms.ROOM_TYPES}


def rank_correlation(stats: HouseStats) -> tuple[float, float, int]:
    """Spearman correlation of our adjacency frequencies with the reference prior.

    Pairs that never co-occur in ``stats`` (NaN) are left out.

    Returns:
      (rho, p-value, number of pairs used).
    """
    ref = reference_adjacency()
    pairs = [p for p in PAIRS if not np.isnan(stats.adjacency[p])]
    if len(pairs) < 3:
        return float("nan"), float("nan"), len(pairs)
    res = scipy.stats.spearmanr([stats.adjacency[p] for p in pairs], [ref[p] for p in pairs])
    return float(res.statistic), float(res.pvalue), len(pairs)


def frequency_error(stats: HouseStats, split: str = "train_200") -> float:
    """Mean absolute difference of the room-type frequencies from the reference."""
    ref = reference_frequency(split)
    return float(np.mean([abs(stats.type_frequency[t] - ref[t]) for t in rooms.ROOM_TYPES]))


def format_report(stats: HouseStats, top: int = 12, markdown: bool = False) -> str:
    """A plain-text (or markdown) report of ``stats`` against the reference."""
    ref_freq = reference_frequency("train_200")
    ref_test = reference_frequency("test_50")
    ref_meta = rooms.reference()["room_type_frequency_in_houses"]
    ref_adj = reference_adjacency()
    rho, pval, n_pairs = rank_correlation(stats)
    lines = []

    def table(header, rows):
        if markdown:
            lines.append("| " + " | ".join(header) + " |")
            lines.append("|" + "|".join("---" if i == 0 else "---:" for i in range(len(header))) + "|")
            lines.extend("| " + " | ".join(r) + " |" for r in rows)
        else:
            widths = [max(len(str(x)) for x in col) for col in zip(header, *rows)]
            fmt = lambda r: "  ".join(  # noqa: E731
                (str(x).ljust(w) if i == 0 else str(x).rjust(w)) for i, (x, w) in enumerate(zip(r, widths))
            )
            lines.append(fmt(header))
            lines.append("  ".join("-" * w for w in widths))
            lines.extend(fmt(r) for r in rows)
        lines.append("")

    lines.append(f"{stats.n_houses} houses")
    lines.append("")
    lines.append("Room-type frequency (fraction of houses with at least one):")
    lines.append("")
    rows = [
        [t, f"{stats.type_frequency[t]:.2f}", f"{ref_freq[t]:.2f}", f"{ref_test[t]:.2f}",
         f"{stats.type_frequency[t] - ref_freq[t]:+.2f}"]
        for t in rooms.ROOM_TYPES
    ]
    rows.append(["indoor (untyped)", f"{stats.type_frequency[rooms.INDOOR]:.2f}", "-", "-", ""])
    table(["room type", "ours", "ref train", "ref test", "ours - train"], rows)
    mean, lo, hi = stats.rooms_per_house
    lines.append(f"Indoor rooms per house: mean {mean:.2f}, min {lo}, max {hi}")
    lines.append(
        f"Distinct target room types per house: {stats.typed_per_house:.2f} "
        f"(reference train {ref_meta['train_200']['mean_room_types_per_house']:.2f}, "
        f"test {ref_meta['test_50']['mean_room_types_per_house']:.2f})"
    )
    lines.append(f"Mean |frequency - reference train|: {frequency_error(stats):.3f}")
    lines.append("")
    for title, dist in (("Indoor rooms per house", stats.rooms_distribution),
                        ("House diameter (longest optimal plan, room-to-room steps)", stats.diameter_distribution)):
        lines.append(f"{title}: houses (fraction)")
        lines.append("")
        table([title.split(" (")[0].lower(), "houses", "fraction"],
              [[str(k), str(v), f"{v / stats.n_houses:.2f}"] for k, v in dist.items()])
    lines.append("Adjacency frequency per type pair (fraction of houses with both types where a door")
    lines.append("joins them) vs the reference prior (random-exploration connectivity, SUNCG):")
    lines.append("")
    order = sorted(PAIRS, key=lambda p: -ref_adj[p])
    rows = [
        [f"{a} - {b}",
         "n/a" if np.isnan(stats.adjacency[(a, b)]) else f"{stats.adjacency[(a, b)]:.2f}",
         f"{ref_adj[(a, b)]:.3f}", str(stats.cooccurrence[(a, b)])]
        for a, b in order
    ]
    table(["pair (by reference)", "ours", "reference", "houses with both"], rows)
    lines.append(
        f"Spearman rank correlation with the reference prior over {n_pairs} pairs "
        f"(pairs never co-occurring left out): rho = {rho:.3f} (p = {pval:.1e})"
    )
    lines.append("")
    ours_top = sorted((p for p in PAIRS if not np.isnan(stats.adjacency[p])),
                      key=lambda p: (-stats.adjacency[p], PAIRS.index(p)))[:top]
    ref_top = order[:top]
    lines.append(f"Strongest {top} pairs:")
    lines.append("")
    rows = [
        [str(i + 1), f"{ours_top[i][0]} - {ours_top[i][1]}", f"{stats.adjacency[ours_top[i]]:.2f}",
         f"{ref_top[i][0]} - {ref_top[i][1]}", f"{ref_adj[ref_top[i]]:.3f}"]
        for i in range(min(top, len(ours_top)))
    ]
    table(["#", "ours", "freq", "reference", "prior"], rows)
    return "\n".join(lines)
