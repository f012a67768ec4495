"""The LEAPS semantic model: a Bayesian graph over room types, and planning on it.

Wu et al. (ICLR 2019) model a house's room layout as a random graph over the
room types. The latent edge ``z_ij`` says whether rooms of types ``i`` and
``j`` are connected in the current house; it is Bernoulli with a prior
``prior_ij`` learned from many houses. While acting, the agent receives noisy
binary observations ``y_ij`` of the edges,

    y | z = 0 ~ Bernoulli(psi_obs0)        (paper: 0.001, false positives)
    y | z = 1 ~ Bernoulli(1 - psi_obs1)    (paper: 0.15, false negatives)

so the exact posterior ``P(z_ij = 1 | Y)`` depends only on the number of
positive and negative observations of each edge. The agent plans the path of
maximum posterior probability to the target and executes its first hop as the
next sub-target. The graph has N = 9 nodes: the 8 room types plus the untyped
``indoor`` node (hallways and other indoor space of no target type).

Everything here is a pure function of arrays, with no MuJoCo, so the planner
and the posterior update can be tested and reused on their own.
"""

import functools
import json
import math
import numbers
import os

import matplotlib.figure
import networkx as nx
import numpy as np
import scipy.special
import scipy.stats

from leaps_mj.world import files, rooms

#: Nodes of the semantic graph: the room types, then ``indoor``.
NUM_NODES = len(rooms.GRAPH_NODES)
#: The paper's observation noise: P(y=1 | z=0) and P(y=0 | z=1).
PAPER_PSI_OBS0 = 0.001
PAPER_PSI_OBS1 = 0.15
#: Path costs this close (relative, or absolute near zero) tie in :meth:`SemanticModel.plan`.
COST_TIE_TOL = 1e-9


def _node(node) -> int:
    """Index of a graph node given as an index or a room-type name.

    Raises:
      ValueError: naming the value when it is neither a known name nor an
        index in ``[0, NUM_NODES)``.
    """
    if isinstance(node, str):
        return rooms.room_index(node)
    if isinstance(node, numbers.Integral) and not isinstance(node, (bool, np.bool_)):
        if 0 <= node < NUM_NODES:
            return int(node)
    raise ValueError(
        f"bad graph node {node!r}; expected a room type in {list(rooms.GRAPH_NODES)} "
        f"or an index in [0, {NUM_NODES})"
    )


def _edge(i, j) -> tuple[int, int]:
    """Both endpoints of an edge as indices; the graph has no self-loops.

    Raises:
      ValueError: if an endpoint is not a node, or both are the same node.
    """
    a, b = _node(i), _node(j)
    if a == b:
        raise ValueError(f"edge ({i!r}, {j!r}) is a self-loop; expected two different nodes")
    return a, b


def _as_bool(value, name: str) -> bool:
    """A flag given as a bool or 0/1.

    Raises:
      ValueError: naming the value when it is anything else.
    """
    if isinstance(value, (bool, np.bool_)) or (
        isinstance(value, numbers.Integral) and value in (0, 1)
    ):
        return bool(value)
    raise ValueError(f"{name} must be a bool (or 0/1), got {value!r}")


def _bool_array(values, shape_desc: str, name: str) -> np.ndarray:
    """Array of flags given as bools or 0/1 values.

    Raises:
      ValueError: naming the offending values when some are not 0/1.
    """
    arr = np.asarray(values)
    if arr.dtype != bool and not np.isin(arr, (0, 1)).all():
        raise ValueError(f"{name} must hold bools or 0/1, got {arr.tolist()} ({shape_desc})")
    return arr.astype(bool)


def _check_square(arr: np.ndarray, name: str) -> None:
    """Raise ValueError unless ``arr`` is NUM_NODES x NUM_NODES."""
    if arr.shape != (NUM_NODES, NUM_NODES):
        raise ValueError(
            f"{name} has shape {arr.shape}; expected ({NUM_NODES}, {NUM_NODES}) over "
            f"{list(rooms.GRAPH_NODES)}"
        )


def _validate_prior(prior) -> np.ndarray:
    """A read-only float copy of a prior with its (meaningless) diagonal set to 1.

    Raises:
      ValueError: if the shape is not (9, 9), an off-diagonal entry is outside
        the open interval (0, 1), or the matrix is not symmetric within 1e-6.
    """
    arr = np.array(prior, dtype=np.float64)
    _check_square(arr, "prior")
    np.fill_diagonal(arr, 1.0)
    off = ~np.eye(NUM_NODES, dtype=bool)
    bad = off & ~((arr > 0.0) & (arr < 1.0))
    if bad.any():
        i, j = np.argwhere(bad)[0]
        raise ValueError(
            f"prior[{i}, {j}] ({rooms.GRAPH_NODES[i]}-{rooms.GRAPH_NODES[j]}) = {arr[i, j]!r}; "
            "expected a probability strictly between 0 and 1"
        )
    asym = np.abs(arr - arr.T)
    if asym.max() > 1e-6:
        i, j = np.unravel_index(np.argmax(asym), asym.shape)
        raise ValueError(
            f"prior is not symmetric: prior[{i}, {j}] = {arr[i, j]!r} but "
            f"prior[{j}, {i}] = {arr[j, i]!r}; expected equal within 1e-6"
        )
    arr = (arr + arr.T) / 2.0
    arr.setflags(write=False)
    return arr


def _validate_psi(value, name: str) -> float:
    """Observation-noise probability in [0, 1).

    Raises:
      ValueError: naming the value when it is not a number in [0, 1).
    """
    if isinstance(value, numbers.Real) and not isinstance(value, (bool, np.bool_)):
        if 0.0 <= value < 1.0:
            return float(value)
    raise ValueError(f"{name} = {value!r}; expected a probability in [0, 1)")


def _validate_counts(counts, name: str) -> np.ndarray:
    """Symmetric non-negative integer count matrix with a zero diagonal.

    Raises:
      ValueError: on a bad shape, negative or non-integer entries, a non-zero
        diagonal, or asymmetry.
    """
    arr = np.asarray(counts)
    _check_square(arr, name)
    integral = np.issubdtype(arr.dtype, np.number) and np.all(arr == np.round(arr))
    if not integral or (arr < 0).any():
        raise ValueError(f"{name} must hold non-negative integers, got {arr.tolist()}")
    arr = arr.astype(np.int64)
    if np.diag(arr).any():
        raise ValueError(f"{name} has non-zero diagonal {np.diag(arr).tolist()}; expected zeros")
    if not np.array_equal(arr, arr.T):
        raise ValueError(f"{name} is not symmetric: {arr.tolist()}")
    return arr


def seen_vector(type_bits_history) -> np.ndarray:
    """Which graph nodes the agent was in during a window of steps.

    The environment reports, per step, the K = 8 room-type bits of the
    agent's location. Indoor space of no target type has all bits zero, so a
    step with all bits zero puts the agent on the ``indoor`` node.

    Args:
      type_bits_history: array of shape (T, 8) of bools or 0/1, one row per step.

    Returns:
      Length-9 bool vector: the OR of the rows, with index 8 (``indoor``) on
      when any row was all zero. All false for an empty window.

    Raises:
      ValueError: if the array is not (T, 8) or holds values other than 0/1.
    """
    bits = np.asarray(type_bits_history)
    if bits.ndim != 2 or bits.shape[1] != rooms.NUM_ROOM_TYPES:
        raise ValueError(
            f"type_bits_history has shape {bits.shape}; expected (T, {rooms.NUM_ROOM_TYPES}), "
            f"one row of room-type bits {list(rooms.ROOM_TYPES)} per step"
        )
    bits = _bool_array(bits, f"shape {bits.shape}", "type_bits_history")
    return np.append(bits.any(axis=0), (~bits.any(axis=1)).any())


def _dijkstra_max_product(costs: np.ndarray, starts: list[int], target: int) -> list[int] | None:
    """Cheapest path from any start to the target, ties broken deterministically.

    A label-setting Dijkstra over labels ``(cost, path)`` ordered by cost,
    then number of hops, then the node sequence lexicographically. Costs
    within :data:`COST_TIE_TOL` of each other are ties, so float rounding in
    sums of -log beliefs does not decide between equally likely paths. The
    order is preserved by extending two labels with the same edge and edge
    costs are non-negative, so the first label settled at the target is the
    best one.

    Args:
      costs: (N, N) non-negative edge costs; ``inf`` means no edge.
      starts: start nodes (cost 0).
      target: goal node.

    Returns:
      The node sequence, or None when no finite-cost path exists.
    """

    def compare(a, b):
        (cost_a, path_a), (cost_b, path_b) = a, b
        if not math.isclose(cost_a, cost_b, rel_tol=COST_TIE_TOL, abs_tol=COST_TIE_TOL):
            return -1 if cost_a < cost_b else 1
        key_a, key_b = (len(path_a), path_a), (len(path_b), path_b)
        return (key_a > key_b) - (key_a < key_b)

    key = functools.cmp_to_key(compare)
    best = {s: (0.0, (s,)) for s in starts}
    settled = set()
    while len(settled) < len(best):
        u = min((v for v in best if v not in settled), key=lambda v: key(best[v]))
        if u == target:
            return list(best[u][1])
        settled.add(u)
        cost_u, path_u = best[u]
        for v in range(len(costs)):
            if v in settled or v == u or not np.isfinite(costs[u, v]):
                continue
            label = (cost_u + costs[u, v], path_u + (v,))
            if v not in best or compare(label, best[v]) < 0:
                best[v] = label
    return None


class SemanticModel:
    """Bayesian room-connectivity graph: prior, noisy observations, posterior, plan.

    Two observation rules feed the per-edge counts (use one per agent):

    * The paper's rule, :meth:`observe_bits`: after a sub-policy runs for N
      steps, every pair of nodes both visited gives y = 1 and every pair with
      exactly one visited gives y = 0; pairs with neither visited are not
      observed. Every edge from a visited to an unvisited node takes the same
      negative, so a failed run changes the plan mainly where it also
      confirmed (y = 1) an edge of an alternative route.
    * The original release's rule, :meth:`observe_subtarget_outcome`: a
      sub-policy run from the current node towards a sub-target gives one
      observation of that edge, y = 1 if it reached the sub-target and y = 0
      if not. (The release also counted co-visited pairs as positives; its
      pair counter had an indexing bug that is not reproduced here.)

    Attributes:
      prior: read-only (9, 9) symmetric prior P(z_ij = 1); diagonal set to 1.
      psi_obs0: P(y = 1 | z = 0).
      psi_obs1: P(y = 0 | z = 1).
      n_pos: (9, 9) symmetric int counts of positive observations per edge.
      n_neg: (9, 9) symmetric int counts of negative observations per edge.
    """

    def __init__(
        self,
        prior,
        psi_obs0: float = PAPER_PSI_OBS0,
        psi_obs1: float = PAPER_PSI_OBS1,
        n_pos=None,
        n_neg=None,
    ):
        """Validates and stores the model; counts default to zero (no evidence).

        Args:
          prior: (9, 9) symmetric matrix over :data:`rooms.GRAPH_NODES`,
            off-diagonal entries in (0, 1); the diagonal is ignored.
          psi_obs0: false-positive rate P(y = 1 | z = 0), in [0, 1).
          psi_obs1: false-negative rate P(y = 0 | z = 1), in [0, 1).
          n_pos: optional (9, 9) symmetric non-negative positive counts.
          n_neg: optional (9, 9) symmetric non-negative negative counts.

        Raises:
          ValueError: naming the bad argument and what was expected.
        """
        self.prior = _validate_prior(prior)
        self.psi_obs0 = _validate_psi(psi_obs0, "psi_obs0")
        self.psi_obs1 = _validate_psi(psi_obs1, "psi_obs1")
        zeros = np.zeros((NUM_NODES, NUM_NODES), dtype=np.int64)
        self.n_pos = zeros.copy() if n_pos is None else _validate_counts(n_pos, "n_pos")
        self.n_neg = zeros.copy() if n_neg is None else _validate_counts(n_neg, "n_neg")

    @classmethod
    def from_reference(cls) -> "SemanticModel":
        """The model of the original release: its SUNCG prior and the paper's noise."""
        return cls(rooms.reference_prior(), PAPER_PSI_OBS0, PAPER_PSI_OBS1)

    def num_parameters(self) -> int:
        """Free parameters: one prior per unordered pair of nodes, plus the two noise rates.

        For 9 nodes this is 36 + 2 = 38, the count the paper reports.
        """
        return NUM_NODES * (NUM_NODES - 1) // 2 + 2

    def reset(self) -> None:
        """Forget all observations: a new house starts again from the prior."""
        self.n_pos[:] = 0
        self.n_neg[:] = 0

    def observe(self, i, j, y) -> None:
        """Record one observation y of the edge between nodes i and j.

        Args:
          i, j: two different nodes (indices or room-type names).
          y: True for "connected", False for "not connected".

        Raises:
          ValueError: on a bad node, a self-loop, or a non-boolean y.
        """
        a, b = _edge(i, j)
        counts = self.n_pos if _as_bool(y, "y") else self.n_neg
        counts[a, b] += 1
        counts[b, a] += 1

    def observe_bits(self, seen) -> None:
        """Apply the paper's rule to the nodes visited during one sub-policy run.

        Pairs with both nodes visited get a positive observation, pairs with
        exactly one visited a negative one, pairs with neither nothing.

        Args:
          seen: length-9 bools over :data:`rooms.GRAPH_NODES`, e.g. from
            :func:`seen_vector` (index 8 on if the agent was in untyped
            indoor space).

        Raises:
          ValueError: if ``seen`` is not 9 bools / 0-1 values.
        """
        arr = np.asarray(seen)
        if arr.shape != (NUM_NODES,):
            raise ValueError(
                f"seen has shape {arr.shape}; expected ({NUM_NODES},) over "
                f"{list(rooms.GRAPH_NODES)} (see seen_vector)"
            )
        on = _bool_array(arr, f"shape {arr.shape}", "seen")
        off_diagonal = ~np.eye(NUM_NODES, dtype=bool)
        self.n_pos += np.outer(on, on) & off_diagonal
        self.n_neg += np.outer(on, ~on) | np.outer(~on, on)

    def observe_subtarget_outcome(self, current_node, subtarget_node, reached) -> None:
        """Apply the original release's rule to one sub-policy run.

        Args:
          current_node: the node the run started from.
          subtarget_node: the sub-target it tried to reach.
          reached: whether it got there; True gives one positive, False one
            negative observation of that edge.

        Raises:
          ValueError: on a bad node, equal nodes, or a non-boolean ``reached``.
        """
        self.observe(current_node, subtarget_node, _as_bool(reached, "reached"))

    def log_posterior(self) -> np.ndarray:
        """(9, 9) log P(z_ij = 1 | Y), exact and stable for any counts.

        With a positives and b negatives on an edge,
        P(z=1 | Y) ∝ prior (1 - psi1)^a psi1^b and
        P(z=0 | Y) ∝ (1 - prior) psi0^a (1 - psi0)^b, normalised in log space.
        The diagonal is 0 (probability 1).

        Raises:
          ValueError: if an edge's observations are impossible under both
            z = 0 and z = 1 (only possible when both noise rates are 0).
        """
        log_one = (
            np.log(self.prior)
            + scipy.special.xlogy(self.n_pos, 1.0 - self.psi_obs1)
            + scipy.special.xlogy(self.n_neg, self.psi_obs1)
        )
        with np.errstate(divide="ignore"):  # the diagonal is 1; overwritten below
            log_prior_zero = np.log1p(-self.prior)
        log_zero = (
            log_prior_zero
            + scipy.special.xlogy(self.n_pos, self.psi_obs0)
            + scipy.special.xlogy(self.n_neg, 1.0 - self.psi_obs0)
        )
        impossible = np.isneginf(log_one) & np.isneginf(log_zero)
        if impossible.any():
            i, j = np.argwhere(impossible)[0]
            raise ValueError(
                f"observations of edge ({rooms.GRAPH_NODES[i]}, {rooms.GRAPH_NODES[j]}): "
                f"{self.n_pos[i, j]} positive and {self.n_neg[i, j]} negative are impossible "
                f"with psi_obs0 = {self.psi_obs0} and psi_obs1 = {self.psi_obs1}; expected "
                "a non-zero noise rate"
            )
        log_post = log_one - np.logaddexp(log_one, log_zero)
        np.fill_diagonal(log_post, 0.0)
        return log_post

    def posterior(self) -> np.ndarray:
        """(9, 9) symmetric P(z_ij = 1 | Y); diagonal 1. See :meth:`log_posterior`."""
        return np.exp(self.log_posterior())

    def plan(self, start_nodes, target) -> list[int]:
        """Most probable path from any current node to the target.

        Maximises the product of posterior edge beliefs, i.e. Dijkstra on
        edge costs -log P(z_ij = 1 | Y) (computed in log space, so tiny
        beliefs stay finite). Ties, up to :data:`COST_TIE_TOL` in cost,
        go to the path with fewer hops, then to the lexicographically smaller
        node sequence (so to the smaller start index among equal starts).

        Args:
          start_nodes: the node(s) the agent is in, a single node or an
            iterable of nodes (indices or room-type names).
          target: the target node.

        Returns:
          Node indices from the chosen start to the target; ``[target]`` if
          the target is a start node.

        Raises:
          ValueError: on bad nodes, no start node, or no path with non-zero
            probability.
        """
        if isinstance(start_nodes, (str, numbers.Integral)):
            start_nodes = [start_nodes]
        starts = sorted({_node(s) for s in start_nodes})
        if not starts:
            raise ValueError(f"start_nodes {start_nodes!r} is empty; expected at least one node")
        goal = _node(target)
        if goal in starts:
            return [goal]
        path = _dijkstra_max_product(-self.log_posterior(), starts, goal)
        if path is None:
            raise ValueError(
                f"no path of non-zero probability from {[rooms.GRAPH_NODES[s] for s in starts]} "
                f"to {rooms.GRAPH_NODES[goal]}"
            )
        return path

    def next_subtarget(self, start_nodes, target) -> int:
        """First hop of :meth:`plan`: the sub-target to run a sub-policy for.

        Returns the target itself when the agent is already there.
        """
        path = self.plan(start_nodes, target)
        return path[1] if len(path) > 1 else path[0]

    def to_json(self, path, include_counts: bool = False) -> None:
        """Write the model as readable JSON, atomically.

        Args:
          path: destination file.
          include_counts: also store the observation counts (a snapshot of a
            posterior rather than just the model).
        """
        data = {
            "rooms": list(rooms.GRAPH_NODES),
            "prior": self.prior.tolist(),
            "psi_obs0": self.psi_obs0,
            "psi_obs1": self.psi_obs1,
        }
        if include_counts:
            data["n_pos"] = self.n_pos.tolist()
            data["n_neg"] = self.n_neg.tolist()
        text = json.dumps(data, indent=1) + "\n"
        files.write_atomic(path, text.encode())

    @classmethod
    def from_json(cls, path) -> "SemanticModel":
        """Load a model written by :meth:`to_json`.

        Raises:
          ValueError: naming the file and the problem if it is missing, not
            JSON, lacks a field, lists other rooms, or holds invalid values.
        """
        try:
            with open(path) as f:
                data = json.load(f)
        except (OSError, json.JSONDecodeError) as e:
            raise ValueError(f"cannot read semantic model from {os.fspath(path)!r}: {e}") from e
        try:
            if not isinstance(data, dict):
                raise ValueError(f"top level is {type(data).__name__}; expected an object")
            missing = [k for k in ("rooms", "prior", "psi_obs0", "psi_obs1") if k not in data]
            if missing:
                raise ValueError(f"missing fields {missing}")
            if data["rooms"] != list(rooms.GRAPH_NODES):
                raise ValueError(f"rooms {data['rooms']!r}; expected {list(rooms.GRAPH_NODES)}")
            return cls(
                data["prior"], data["psi_obs0"], data["psi_obs1"], data.get("n_pos"), data.get("n_neg")
            )
        except ValueError as e:
            raise ValueError(f"bad semantic model file {os.fspath(path)!r}: {e}") from e


def learn_prior(pos_counts, trials, floor: float = 1e-4) -> np.ndarray:
    """Maximum-likelihood prior from random-exploration statistics.

    For each pair, the prior is the fraction of exploration trials in which
    the two rooms were seen connected. Counts are pooled over both orders
    (``pos + pos.T`` over ``trials + trials.T``), so callers may fill one
    triangle or both. The estimate is clipped to ``[floor, 1 - floor]`` so
    no edge is ever impossible or certain; pairs never tried (e.g. a room
    type absent from every house) get ``floor``: with no evidence of a
    connection, the planner should avoid them. The diagonal is 1.

    Args:
      pos_counts: (9, 9) non-negative counts of trials with the pair connected.
      trials: (9, 9) non-negative trial counts, or one number for all pairs.
      floor: clip bound in (0, 0.5).

    Returns:
      (9, 9) symmetric prior over :data:`rooms.GRAPH_NODES`.

    Raises:
      ValueError: on bad shapes, negative counts, more positives than
        trials, or a floor outside (0, 0.5).
    """
    if not 0.0 < floor < 0.5:
        raise ValueError(f"floor = {floor!r}; expected a number in (0, 0.5)")
    pos = np.asarray(pos_counts, dtype=np.float64)
    _check_square(pos, "pos_counts")
    tri = np.asarray(trials, dtype=np.float64)
    if tri.ndim == 0:
        tri = np.full(pos.shape, tri)
    _check_square(tri, "trials")
    for name, arr in (("pos_counts", pos), ("trials", tri)):
        if (arr < 0).any() or not np.isfinite(arr).all():
            raise ValueError(f"{name} must be finite and non-negative, got {arr.tolist()}")
    over = pos > tri
    if over.any():
        i, j = np.argwhere(over)[0]
        raise ValueError(
            f"pos_counts[{i}, {j}] = {pos[i, j]:g} exceeds trials[{i}, {j}] = {tri[i, j]:g}; "
            "expected at most one positive per trial"
        )
    pos, tri = pos + pos.T, tri + tri.T
    with np.errstate(invalid="ignore", divide="ignore"):
        frac = np.where(tri > 0, pos / tri, floor)
    prior = np.clip(frac, floor, 1.0 - floor)
    np.fill_diagonal(prior, 1.0)
    return prior


def rank_correlation(a, b) -> float:
    """Spearman rank correlation of two priors over their 36 distinct pairs.

    Compares the ordering of edges (e.g. a prior learned on generated houses
    against the SUNCG reference), ignoring the meaningless diagonal.

    Raises:
      ValueError: on shapes other than (9, 9) or a prior whose off-diagonal
        entries are all equal (rank correlation undefined).
    """
    iu = np.triu_indices(NUM_NODES, k=1)
    values = []
    for name, m in (("a", a), ("b", b)):
        arr = np.asarray(m, dtype=np.float64)
        _check_square(arr, name)
        if np.ptp(arr[iu]) == 0:
            raise ValueError(
                f"{name} has all off-diagonal entries equal to {arr[iu][0]!r}; "
                "expected varying values (rank correlation is undefined)"
            )
        values.append(arr[iu])
    return float(scipy.stats.spearmanr(*values).statistic)


def _label(node: int) -> str:
    """Display name of a node ("dining_room" -> "dining room")."""
    return rooms.GRAPH_NODES[node].replace("_", " ")


def _draw_graph(ax, weights: np.ndarray, highlight_path=None) -> None:
    """Draw the 9-node graph on ``ax`` with edge width and opacity growing with weight.

    Args:
      ax: matplotlib axes.
      weights: (9, 9) symmetric edge probabilities in [0, 1].
      highlight_path: optional node sequence whose edges are drawn in red on top.
    """
    pos = nx.circular_layout(range(NUM_NODES))
    edges = sorted((weights[i, j], i, j) for i in range(NUM_NODES) for j in range(i + 1, NUM_NODES))
    for w, i, j in edges:
        (x0, y0), (x1, y1) = pos[i], pos[j]
        ax.plot([x0, x1], [y0, y1], color="tab:blue", lw=0.3 + 7.0 * w, alpha=0.08 + 0.8 * w,
                solid_capstyle="round", zorder=1)
    if highlight_path is not None:
        nodes = [_node(n) for n in highlight_path]
        for u, v in zip(nodes, nodes[1:]):
            (x0, y0), (x1, y1) = pos[u], pos[v]
            ax.plot([x0, x1], [y0, y1], color="tab:red", lw=3.5, zorder=2)
    xy = np.array([pos[n] for n in range(NUM_NODES)])
    ax.scatter(xy[:, 0], xy[:, 1], s=140, color="white", edgecolors="black", zorder=3)
    for n, (x, y) in enumerate(xy):
        ha = "left" if x > 0.3 else "right" if x < -0.3 else "center"
        va = "bottom" if y > 0.3 else "top" if y < -0.3 else "center"
        ax.text(1.12 * x, 1.12 * y, _label(n), ha=ha, va=va, fontsize=9, zorder=4)
    ax.set_xlim(-1.7, 1.7)
    ax.set_ylim(-1.3, 1.3)
    ax.set_aspect("equal")
    ax.axis("off")


def plot_prior(prior, path, rooms=("dining_room", "bedroom", "outdoor")) -> None:
    """Save a figure like the paper's Fig. 2: neighbour priors per room, and the graph.

    One horizontal bar chart per listed room, its 8 neighbours sorted from
    most to least likely, then the whole graph with edge width and opacity
    proportional to the prior. Rendered off-screen (Agg canvas, no pyplot
    state) and written atomically as PNG.

    Args:
      prior: (9, 9) prior over :data:`rooms.GRAPH_NODES`.
      path: destination PNG file.
      rooms: room types (or indices) to give a bar chart. (This argument
        shadows the ``rooms`` module inside this function.)

    Raises:
      ValueError: on an invalid prior or an unknown room.
    """
    prior = _validate_prior(prior)
    shown = [_node(r) for r in rooms]
    fig = matplotlib.figure.Figure(figsize=(3.6 * len(shown) + 5.5, 4.2), layout="constrained")
    axes = fig.subplots(1, len(shown) + 1, squeeze=False, width_ratios=[1.0] * len(shown) + [1.6])[0]
    for ax, node in zip(axes, shown):
        others = sorted((n for n in range(NUM_NODES) if n != node), key=lambda n: (-prior[node, n], n))
        values = [prior[node, n] for n in others]
        ax.barh(range(len(others)), values, color="tab:blue", alpha=0.8)
        ax.set_yticks(range(len(others)), [_label(n) for n in others])
        ax.invert_yaxis()
        ax.set_xlim(0.0, 1.0)
        ax.set_xlabel("prior P(connected)")
        ax.set_title(_label(node))
        for k, v in enumerate(values):
            ax.text(v + 0.02, k, f"{v:.2f}", va="center", fontsize=8)
    _draw_graph(axes[-1], prior)
    axes[-1].set_title("room-connectivity prior")
    files.write_atomic_with(path, lambda tmp: fig.savefig(tmp, format="png", dpi=120))


def plot_belief(model: SemanticModel, ax, highlight_path=None):
    """Draw the model's current posterior as a graph on ``ax``.

    Edge width and opacity grow with the belief P(z_ij = 1 | Y); the planned
    path, if given, is drawn in red. Used for case-study figures.

    Args:
      model: the semantic model.
      ax: matplotlib axes to draw on.
      highlight_path: optional node sequence (indices or names), e.g. from
        :meth:`SemanticModel.plan`.

    Returns:
      ``ax``.
    """
    _draw_graph(ax, model.posterior(), highlight_path)
    return ax
