"""The hop benchmark: how often a sub-policy reaches a room one or two doors away.

``python -m leaps_mj.evaluation.hops --dataset roomnav-v1 --split test --out results/hops_shipped_v1_test``

LEAPS hands control to a sub-policy for at most N = 30 steps towards a
neighbouring room, so its success rests on that hop. The hop episodes
(``houses/<dataset>/episodes/hops_<split>.jsonl``, written by
``python tools/make_episodes.py --hops``, see
:func:`leaps_mj.environment.episodes.generate_hops`) start 1 and 2 doors from
the nearest room of each graph node (the 8 room types and the untyped
``indoor`` node). Each agent runs the target's sub-policy alone (``pure``,
:class:`leaps_mj.planning.agents.PureAgent`), the geodesic ``oracle``, or the
``observable`` expert (the teacher that chooses only from what the agent has
seen, :class:`leaps_mj.environment.observable_expert.ObservableExpert`);
success is the environment's own (the see test, 3 steps in a row; for
``indoor`` being in untyped indoor space). Each episode runs once to the
largest horizon and success within a smaller one is derived from the success
step, through :func:`leaps_mj.evaluation.harness.run` (resumable CSVs, worker
processes or Ray actors with ``--backend ray``, the same per-episode seeds for every agent and
sub-policy).

``--large`` runs the large hop set instead (``hops_large_<split>.jsonl``, written by
``python tools/make_episodes.py --hops --large``): 100 starts per node and distance drawn
with another seed, for differences of a few points and for a figure on starts no training
decision was made on.

``--policy-dir DIR`` runs the checkpoints of a newly trained set
(``DIR/<node>.pt``) instead of the shipped ones; ``--baseline FOLDER`` pairs
its ``pure`` results with those of an earlier run on the same episodes and
reports the exact McNemar p-value per distance and per node:

``python -m leaps_mj.evaluation.hops --dataset roomnav-v1 --split test --policy-dir runs/policy_new --baseline results/hops_shipped_v1_test --out results/hops_new_test``

Outputs in ``--out``: the harness's ``config.json`` and ``episodes_<agent>.csv``;
``results.md`` and ``summary.json`` (success per agent, distance, node and
horizon with 95 % Wilson intervals, and the paired comparison); ``hop_success.png``.
"""

from __future__ import annotations

import argparse
import json
import math
import pathlib
import sys

import numpy as np

from leaps_mj.environment import episodes as episodes_lib
from leaps_mj.evaluation import backends, harness, stats
from leaps_mj.world import dataset as dataset_lib
from leaps_mj.world import files
from leaps_mj.world import rooms

#: Step budgets reported: one LEAPS hand-over (N = 30) and two.
HORIZONS = (30, 60)
#: Agents of the benchmark (names of :data:`leaps_mj.evaluation.harness.AGENTS`).
AGENTS = ("pure", "oracle", "oracle-scan", "oracle-look", "oracle-map", "oracle-map-observable", "oracle-map-furniture",
          "oracle-map-sensed", "oracle-map-gated", "oracle-map-potential", "observable", "frontier", "random")
#: Named subsets: episodes per node and door distance (None: all).
SUBSETS = {"full": None, "smoke": 1}
#: The label of a run's sub-policy results, the one paired with a baseline's.
PAIRED_LABEL = "pure"
#: Edges (metres) of the bins of the start's geodesic distance in :func:`by_geodesic`: fixed, so that runs compare.
GEODESIC_EDGES = (0.0, 5.0, 10.0, 15.0, math.inf)


def _stratum(spec) -> tuple[int, int]:
    """An episode's (node index, door distance): the unit of the tables and of subsets."""
    return rooms.room_index(spec.target), spec.plan_length


def _groups(rows: list[dict]) -> dict:
    """Masks over the rows per door distance: ``{str(d): {"all": mask, "node": {node: mask}}}`` (empty nodes left out)."""
    dist = np.array([r["plan_length"] for r in rows])
    node = np.array([r["target"] for r in rows])
    out = {}
    for d in sorted(set(dist.tolist())):
        m = dist == d
        out[str(d)] = {"all": m, "node": {n: m & (node == n) for n in rooms.GRAPH_NODES if np.any(m & (node == n))}}
    return out


def _per_group(groups: dict, fn) -> dict:
    """``fn(mask)`` for every mask of :func:`_groups`, in the same layout."""
    return {d: {"all": fn(g["all"]), "node": {n: fn(m) for n, m in g["node"].items()}} for d, g in groups.items()}


def summarize(table: dict[str, list[dict]], horizons) -> dict:
    """Success rates per agent, horizon and door distance: overall and per node.

    Returns:
      ``{label: {str(H): {str(d): {"all": rate, "node": {node: rate}}}}}`` (rates of
      :func:`leaps_mj.evaluation.stats.rate`; nodes without episodes left out).
    """
    out = {}
    for label, rows in table.items():
        groups = _groups(rows)
        out[label] = {}
        for h in horizons:
            s = stats.success_at(rows, h)
            out[label][str(h)] = _per_group(groups, lambda m, s=s: stats.rate(s[m]))
    return out


def _bin_name(lo: float, hi: float) -> str:
    return f"{lo:g}-{hi:g} m" if math.isfinite(hi) else f">= {lo:g} m"


def by_geodesic(table: dict[str, list[dict]], horizon: int) -> dict:
    """Success within ``horizon`` per agent, door distance and bin of the start's geodesic distance.

    A door away can mean 2 m or 30 m (a garage across a yard): these bins (:data:`GEODESIC_EDGES`) show
    whether an agent fails on choosing the way or on hops that 60 steps cannot walk.

    Returns:
      ``{label: {str(d): {"lo-hi m": rate}}}`` (empty bins left out).
    """
    out = {}
    for label, rows in table.items():
        s = stats.success_at(rows, horizon)
        doors = np.array([r["plan_length"] for r in rows])
        metres = np.array([r["geodesic"] for r in rows], dtype=float)
        out[label] = {}
        for d in sorted(set(doors.tolist())):
            bins = {}
            for lo, hi in zip(GEODESIC_EDGES[:-1], GEODESIC_EDGES[1:]):
                m = (doors == d) & (metres >= lo) & (metres < hi)
                if m.any():
                    bins[_bin_name(lo, hi)] = stats.rate(s[m])
            out[label][str(d)] = bins
    return out


def check_baseline(folder: pathlib.Path, config: harness.EvalConfig) -> None:
    """Checks that a result folder is a hop run comparable with ``config``.

    Raises:
      ValueError: unless it is a hop run of the same dataset, split, seed and hop set
        (the same episodes and per-episode seeds) with at least this horizon.
    """
    path = folder / "config.json"
    if not path.is_file():
        raise ValueError(f"baseline {str(folder)!r} holds no config.json: expected a hop benchmark result folder")
    saved = {**harness.LATER_FIELDS, **json.loads(path.read_text())}
    want = {"dataset": config.dataset, "split": config.split, "seed": config.seed, "episodes": config.episodes}
    diff = {k: (saved.get(k), v) for k, v in want.items() if saved.get(k) != v}
    if saved.get("horizon", 0) < config.horizon:
        diff["horizon"] = (saved.get("horizon"), f">= {config.horizon}")
    if diff:
        raise ValueError(f"baseline {str(folder)!r} is not comparable (baseline, here): {diff}")


def load_baseline(folder: pathlib.Path, config: harness.EvalConfig, rows: list[dict]) -> list[dict]:
    """The baseline run's ``pure`` rows of the same episodes as ``rows``, checked to be comparable.

    Raises:
      ValueError: if :func:`check_baseline` fails, the folder lacks some of
        the episodes, or its episodes differ (the hop file was regenerated in between).
    """
    check_baseline(folder, config)
    by_episode = {r["episode"]: r for r in harness.read_rows(harness.csv_path(folder, PAIRED_LABEL))}
    missing = [r["episode"] for r in rows if r["episode"] not in by_episode]
    if missing:
        raise ValueError(f"baseline {str(folder)!r} lacks {len(missing)} of the {len(rows)} episodes "
                         f"(e.g. {missing[:3]}); rerun it with the same selection")
    keys = ("house", "target", "plan_length", "geodesic")
    changed = [r["episode"] for r in rows if any(r[k] != by_episode[r["episode"]][k] for k in keys)]
    if changed:
        raise ValueError(f"baseline {str(folder)!r} ran other episodes under the same indices (e.g. {changed[:3]}): "
                         "the hop file changed since; rerun the baseline")
    return [by_episode[r["episode"]] for r in rows]


def compare(rows: list[dict], base: list[dict], horizons) -> dict:
    """Paired test (:func:`leaps_mj.evaluation.stats.paired_test`, a = this run, b = the baseline).

    Returns:
      ``{str(H): {str(d): {"all": test, "node": {node: test}}}}``.
    """
    groups = _groups(rows)
    out = {}
    for h in horizons:
        a, b = stats.success_at(rows, h), stats.success_at(base, h)
        out[str(h)] = _per_group(groups, lambda m, a=a, b=b: stats.paired_test(a[m], b[m]))
    return out


# -- report -------------------------------------------------------------------------


def _doors(d) -> str:
    return f"{d} door" + ("s" if int(d) != 1 else "")


def _cell(r: dict) -> str:
    return f"{100 * r['rate']:.1f}% [{100 * r['low']:.1f}, {100 * r['high']:.1f}]"


def _policy_name(config: harness.EvalConfig) -> str:
    if config.subpolicy == "local":
        return "the local expert (privileged)"
    shipped = "learned, shipped μ(θ) (`leaps_mj/data/policies/cpu`)"
    which = f"learned, `{config.policy_dir}`" if config.policy_dir else shipped
    return which if config.temperature == 1.0 else f"{which}, sampled at temperature {config.temperature:g}"


def markdown(summary: dict, horizons, config: harness.EvalConfig, comparison: dict | None = None,
             baseline: pathlib.Path | None = None, geodesic: dict | None = None) -> str:
    """The hop results as markdown: overall, per node for each distance, by the start's geodesic distance
    (``geodesic``: :func:`by_geodesic` at the longest horizon), and the paired comparison."""
    labels = list(summary)
    hs = [str(h) for h in horizons]
    distances = list(summary[labels[0]][hs[0]])
    n = sum(summary[labels[0]][hs[0]][d]["all"]["n"] for d in distances)
    lines = [
        f"# Hop benchmark: {config.dataset} / {config.split}",
        "",
        (f"{n} hop episodes (starts 1 or 2 doors from the nearest room of the node); sub-policy "
         f"{_policy_name(config)}; seed {config.seed}. Success = the environment's see test within H steps "
         f"(`indoor`: in untyped indoor space), with a 95% Wilson interval; each episode ran once to "
         f"H = {config.horizon}."),
        "",
        "| agent | " + " | ".join(f"{_doors(d)}, ≤ {h}" for d in distances for h in hs) + " |",
        "|---|" + "---|" * (len(distances) * len(hs)),
    ]
    for label in labels:
        lines.append(f"| {label} | " + " | ".join(_cell(summary[label][h][d]["all"]) for d in distances
                                                 for h in hs) + " |")
    for d in distances:
        lines += ["", f"## {_doors(d)}, per node", "",
                  "| node | n | " + " | ".join(f"{label} ≤ {h}" for label in labels for h in hs) + " |",
                  "|---|---:|" + "---|" * (len(labels) * len(hs))]
        for node in summary[labels[0]][hs[0]][d]["node"]:
            n_node = summary[labels[0]][hs[0]][d]["node"][node]["n"]
            lines.append(f"| {node} | {n_node} | " + " | ".join(
                _cell(summary[label][h][d]["node"][node]) for label in labels for h in hs) + " |")
    if geodesic is not None:
        lines += ["", f"## By the start's geodesic distance, ≤ {hs[-1]}", "",
                  "| doors | metres | n | " + " | ".join(labels) + " |",
                  "|---|---|---:|" + "---|" * len(labels)]
        for d in distances:
            for name, r in geodesic[labels[0]][d].items():
                lines.append(f"| {_doors(d)} | {name} | {r['n']} | " + " | ".join(
                    _cell(geodesic[label][d][name]) for label in labels) + " |")
    if comparison is not None:
        lines += ["", f"## Paired with the baseline `{baseline}` ({PAIRED_LABEL} vs {PAIRED_LABEL})", "",
                  "Exact McNemar (sign) test on the same episodes, two-sided.", "",
                  "| distance | H | node | n | here | baseline | only here | only baseline | p |",
                  "|---|---|---|---:|---:|---:|---:|---:|---:|"]
        for h in hs:
            for d in distances:
                per = comparison[h][d]
                for node, t in [("**all**", per["all"])] + list(per["node"].items()):
                    lines.append(f"| {_doors(d)} | ≤ {h} | {node} | {t['n']} | {t['a']} | {t['b']} | "
                                 f"{t['a_only']} | {t['b_only']} | {t['p']:.3g} |")
    return "\n".join(lines) + "\n"


def plot(summary: dict, horizons, out: pathlib.Path, baseline: dict | None = None) -> pathlib.Path:
    """Bar chart per node and distance: one bar per agent, shaded from the smallest horizon (dark) up.

    Success within a smaller horizon is nested in success within a larger
    one, so the bars of one agent are drawn over each other.
    """
    import matplotlib.pyplot as plt

    from leaps_mj.world import topdown

    series = dict(summary)
    if baseline is not None:
        series[f"baseline {PAIRED_LABEL}"] = baseline
    labels, hs = list(series), [str(h) for h in sorted(horizons, reverse=True)]
    distances = list(summary[labels[0]][hs[0]])
    fig, axes = plt.subplots(len(distances), 1, figsize=(12, 3.6 * len(distances)), squeeze=False,
                             layout="constrained")
    width = 0.8 / len(labels)
    colours = plt.rcParams["axes.prop_cycle"].by_key()["color"]
    for ax, d in zip(axes[:, 0], distances):
        nodes = list(summary[labels[0]][hs[0]][d]["node"]) + ["all"]
        x = np.arange(len(nodes))
        for k, label in enumerate(labels):
            for j, h in enumerate(hs):
                per = series[label][h][d]
                r = [per["all"] if n == "all" else per["node"][n] for n in nodes]
                y = np.array([v["rate"] for v in r])
                err = np.array([[v["rate"] - v["low"] for v in r], [v["high"] - v["rate"] for v in r]])
                pos = x + (k - (len(labels) - 1) / 2) * width
                alpha = 0.35 + 0.65 * j / max(len(hs) - 1, 1)
                ax.bar(pos, y, width * 0.9, color=colours[k % len(colours)], alpha=alpha,
                       label=f"{label}, ≤ {h} steps")
                shift = (j - (len(hs) - 1) / 2) * width * 0.25  # keeps the nested bars' intervals apart
                ax.errorbar(pos + shift, y, yerr=err, fmt="none", ecolor="black", elinewidth=0.8, capsize=2)
        first = summary[labels[0]][hs[0]][d]
        counts = [(first["all"] if n == "all" else first["node"][n])["n"] for n in nodes]
        ax.set_xticks(x, [f"{n}\n(n={c})" for n, c in zip(nodes, counts)], fontsize=8)
        ax.set_ylim(0, 1.02)
        ax.set_ylabel("success (95% Wilson CI)")
        ax.set_title(f"start {_doors(d)} from the node")
        ax.grid(axis="y", alpha=0.3)
    fig.legend(*axes[0, 0].get_legend_handles_labels(), loc="outside upper center", ncol=len(labels) * len(hs),
               fontsize=8)
    path = out / "hop_success.png"
    topdown.save_figure(fig, path)
    return path


def report(table, horizons, config, out: pathlib.Path, baseline: pathlib.Path | None = None) -> dict:
    """Writes ``results.md``, ``summary.json`` and ``hop_success.png``; returns the summary.

    With a baseline folder, the table's ``pure`` rows are paired with the
    baseline's own (see :func:`load_baseline`).
    """
    summary = summarize(table, horizons)
    geodesic = by_geodesic(table, max(horizons))
    comparison, base_summary = None, None
    if baseline is not None:
        base = load_baseline(baseline, config, table[PAIRED_LABEL])
        comparison = compare(table[PAIRED_LABEL], base, horizons)
        base_summary = summarize({PAIRED_LABEL: base}, horizons)[PAIRED_LABEL]
    files.write_atomic(out / "results.md", markdown(summary, horizons, config, comparison, baseline,
                                                              geodesic).encode())
    doc = {"config": config.to_json(), "horizons": list(horizons), "success": summary, "by_geodesic": geodesic}
    if comparison is not None:
        doc["baseline"] = {"folder": str(baseline), "success": base_summary, "paired": comparison}
    files.write_atomic(out / "summary.json", (json.dumps(doc, indent=1) + "\n").encode())
    plot(summary, horizons, out, base_summary)
    return doc


def main(argv=None) -> int:
    p = argparse.ArgumentParser(prog="python -m leaps_mj.evaluation.hops", description=__doc__,
                                formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--agent", nargs="+", choices=list(AGENTS), default=["pure", "oracle"])
    p.add_argument("--dataset", default=dataset_lib.CANONICAL)
    p.add_argument("--split", default="test", choices=["valid", "test"])
    p.add_argument("--horizon", nargs="+", type=int, default=list(HORIZONS),
                   help="step budgets reported; each episode runs to the largest")
    p.add_argument("--out", type=pathlib.Path, required=True, help="result folder (resumable)")
    p.add_argument("--subpolicy", choices=["local", "learned"], default="learned",
                   help="learned: the sub-policies of --policy-dir; local: the privileged local expert")
    p.add_argument("--policy-dir", default=None,
                   help="folder of sub-policy checkpoints to evaluate, or a shipped folder's name: goal_cpu (the "
                        "map-goal sub-policy, the default) or cpu (μ(θ))")
    p.add_argument("--temperature", type=float, default=1.0,
                   help="sampling temperature of the learned sub-policies' actions (1: as trained)")
    p.add_argument("--baseline", type=pathlib.Path, default=None,
                   help="an earlier hop result folder whose pure results are paired with this run's")
    p.add_argument("--subset", choices=list(SUBSETS), default="full",
                   help=f"episodes per node and door distance: {SUBSETS}")
    p.add_argument("--per-node", type=int, default=None, help="episodes per node and distance (overrides --subset)")
    p.add_argument("--large", action="store_true",
                   help="the large hop set (hops_large_<split>.jsonl: 100 starts per node and distance, another draw)")
    p.add_argument("--nodes", nargs="+", choices=list(rooms.GRAPH_NODES), default=None,
                   help="only the episodes towards these nodes (e.g. the ones a new set retrained)")
    p.add_argument("--limit", type=int, default=None, help="only the first N selected episodes")
    backends.add_arguments(p)
    p.add_argument("--seed", type=int, default=0)
    p.add_argument("--no-progress", action="store_true")
    args = p.parse_args(argv)
    horizons = sorted(set(args.horizon))
    if horizons[0] < 1:
        p.error(f"--horizon {args.horizon}: expected positive integers")
    if args.limit is not None and args.limit < 1:
        p.error(f"--limit {args.limit}: expected a positive integer")
    where = backends.from_arguments(p, args)
    kind = "hops_large" if args.large else "hops"
    try:
        config = harness.EvalConfig(dataset=args.dataset, split=args.split, horizon=horizons[-1],
                                    subpolicy=args.subpolicy, seed=args.seed, episodes=kind,
                                    policy_dir=harness.command_line_policy_dir(args.subpolicy, args.policy_dir),
                                    temperature=args.temperature)
        specs = episodes_lib.load_split(args.dataset, args.split, kind)
        # Node filter after the draw: a run on some nodes gets the full run's episodes of those nodes.
        indices = [i for i in episodes_lib.select_episodes(specs, args.per_node or SUBSETS[args.subset],
                                                           seed=args.seed, stratum=_stratum)
                   if args.nodes is None or specs[i].target in args.nodes][:args.limit]
        if "pure" in args.agent and args.subpolicy == "learned":
            _prepare_policies(config, {specs[i].target for i in indices})
        if args.baseline is not None:
            if PAIRED_LABEL not in args.agent:
                raise ValueError(f"--baseline compares the agent {PAIRED_LABEL!r}: add it to --agent")
            check_baseline(args.baseline, config)
        table = harness.run(config, [harness.AGENTS[a] for a in args.agent], indices, args.out,
                            workers=where.workers, progress=not args.no_progress, backend=where.name,
                            ray_address=where.address)
        doc = report(table, horizons, config, args.out, args.baseline)
    except ValueError as e:
        print(f"error: {e}", file=sys.stderr)
        return 2
    print((args.out / "results.md").read_text())
    if "baseline" in doc:
        _print_paired(doc["baseline"]["paired"], horizons)
    return 0


def _prepare_policies(config: harness.EvalConfig, nodes: set[str]) -> None:
    """Sets torch to one thread and loads the sub-policies once, to fail now rather than in a worker.

    One thread, as in the harness's worker processes: several busy threads
    per process on a shared 2-core machine slow the small convolutions down
    many times.

    Raises:
      ValueError: if the sub-policies cannot be loaded or lack a node the selected episodes target.
    """
    import torch

    from leaps_mj.learning import policy_folder

    torch.set_num_threads(1)
    loaded = policy_folder.load(config.policy_dir).targets
    missing = [n for n in rooms.GRAPH_NODES if n in nodes and n not in loaded]
    if missing:
        raise ValueError(f"policy folder {config.policy_dir!r} has no checkpoint for nodes {missing} "
                         f"that the selected hop episodes target; add --nodes {' '.join(loaded)}")


def _print_paired(paired: dict, horizons) -> None:
    """One line per distance and horizon: the overall paired comparison with the baseline."""
    for h in horizons:
        for d, per in paired[str(h)].items():
            t = per["all"]
            diff = (t["a"] - t["b"]) / t["n"] if t["n"] else math.nan
            print(f"paired, {_doors(d)}, <= {h} steps: here {t['a']}/{t['n']}, baseline {t['b']}/{t['n']} "
                  f"({100 * diff:+.1f} points); only here {t['a_only']}, only baseline {t['b_only']}; "
                  f"exact McNemar p = {t['p']:.3g}")


if __name__ == "__main__":
    sys.exit(main())
