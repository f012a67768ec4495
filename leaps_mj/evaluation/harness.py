"""Evaluate agents on the fixed RoomNav episodes: CSVs, a markdown table, the paper's plots.

``python -m leaps_mj.evaluate --agent random pure leaps oracle --split test --horizon 300 500 1000 --out DIR``

Each episode of the split's fixed set (:func:`leaps_mj.environment.episodes.load_split`,
stratified by optimal plan length) is run once per agent at the largest
horizon, recording the step at which it succeeded. Success at a smaller
horizon H is then derived: a success at step t counts for every H >= t. This
is exact because no agent here behaves differently for a different horizon
(none of them sees it); an agent that did would need one run per horizon.

Every episode is seeded from ``SeedSequence([seed, episode index])``, the
same for every agent (common random numbers), so results do not depend on
the number of workers or on the order episodes are run in.

Outputs in ``--out``:

* ``config.json``: what the rows depend on (dataset, split, run horizon,
  sub-policy, prior, N, seed); a later run into the same folder must match it.
* ``episodes_<agent>.csv``: one row per episode, appended atomically after
  every chunk of episodes, so an interrupted run resumes where it stopped
  (episodes already in the CSV are skipped).
* ``results.md`` and ``summary.json``: success rate with a 95% Wilson
  binomial interval per agent and horizon, overall and by plan length, and
  each LEAPS agent paired with each baseline on the same episodes (exact
  McNemar test, :func:`leaps_mj.evaluation.stats.paired_comparisons`).
* ``success_vs_plan_length.png``, ``success_vs_metres.png``,
  ``relative_improvement.png``: the paper's Fig. 4-style plots.

Agent ``aug`` (the semantic-augmented policy μ_s) runs the μ_s trained with
the ``--policy-dir`` folder's recipe where the folder has one (``aug/``), else
the shipped learned μ_s, whatever ``--subpolicy`` says; ``controller`` drives
the ``--subpolicy`` with the folder's own controller (``controller.pt``) or the
shipped one (:mod:`leaps_mj.learning.policy_folder`); ``leaps*`` use ``--subpolicy``.

``--subset quick`` (20 episodes per plan length, 100 on the canonical test
split: the README's main job) is the fixed subset for a short run; ``--subset smoke`` (2 per plan length) checks the
pipeline in seconds.

``--backend ray [--ray-address ADDR] [--workers N]`` runs the same chunks
on Ray actors across a cluster (:mod:`leaps_mj.evaluation.backends`,
docs/ray.md); the CSVs are byte-identical to the local backend's.

The hop benchmark of the sub-policies alone (:mod:`leaps_mj.evaluation.hops`,
``python -m leaps_mj.evaluation.hops``) runs on this machinery with the hop
episodes (``EvalConfig.episodes = "hops"``) and any checkpoint folder
(``EvalConfig.policy_dir``).
"""

from __future__ import annotations

import argparse
import contextlib
import csv
import dataclasses
import io
import json
import math
import pathlib
import sys

import numpy as np
import tqdm

from leaps_mj.environment import episodes as episodes_lib
from leaps_mj.environment import roomnav
from leaps_mj.evaluation import backends, registry, stats
from leaps_mj.planning import agents as agents_lib
from leaps_mj.planning import semantic
from leaps_mj.records import recorder as record_lib
from leaps_mj.world import dataset as dataset_lib
from leaps_mj.world import files


@dataclasses.dataclass(frozen=True)
class AgentSpec:
    """An evaluated agent: a :func:`leaps_mj.evaluation.registry.make_agent` name and its options.

    Attributes:
      label: name in files, tables and plots.
      name: agent name for :func:`leaps_mj.evaluation.registry.make_agent`.
      rule: LEAPS observation rule ("paper" or "release").
      psi_obs: LEAPS observation noise (psi_obs0, psi_obs1) overriding the
        prior file's, or None.
      bits: where the semantic bits come from: "truth" (the house geometry) or a key of
        :data:`CLASSIFIER_BITS`: "classifier" (the CNN room-type classifier, leaps_mj.learning.classifier),
        or, to tell which of the classifier's errors move LEAPS, "classifier-and-truth" (its bits that
        the truth confirms) and "classifier-or-truth" (its bits and the truth's).
    """

    label: str
    name: str
    rule: str = "paper"
    psi_obs: tuple[float, float] | None = None
    bits: str = "truth"


#: The classifier's bit sources (``AgentSpec.bits`` other than "truth"), each with its ``truth`` mode of
#: :class:`leaps_mj.learning.classifier.ClassifierBits`.
CLASSIFIER_BITS = {"classifier": None, "classifier-and-truth": "and", "classifier-or-truth": "or"}

#: Agents selectable with ``--agent``.
AGENTS = {
    "random": AgentSpec("random", "random"),
    "pure": AgentSpec("pure", "pure"),
    "leaps": AgentSpec("leaps", "leaps", rule="paper"),
    "leaps-release": AgentSpec("leaps-release", "leaps", rule="release"),
    "leaps-cnn": AgentSpec("leaps-cnn", "leaps", rule="paper", bits="classifier"),
    "leaps-cnn-and-truth": AgentSpec("leaps-cnn-and-truth", "leaps", rule="paper", bits="classifier-and-truth"),
    "leaps-cnn-or-truth": AgentSpec("leaps-cnn-or-truth", "leaps", rule="paper", bits="classifier-or-truth"),
    "controller": AgentSpec("controller", "controller"),
    "aug": AgentSpec("aug", "aug"),
    "oracle": AgentSpec("oracle", "oracle"),
    "oracle-scan": AgentSpec("oracle-scan", "oracle-scan"),
    "oracle-look": AgentSpec("oracle-look", "oracle-look"),
    "oracle-map": AgentSpec("oracle-map", "oracle-map"),
    "oracle-map-observable": AgentSpec("oracle-map-observable", "oracle-map-observable"),
    "oracle-map-furniture": AgentSpec("oracle-map-furniture", "oracle-map-furniture"),
    "oracle-map-sensed": AgentSpec("oracle-map-sensed", "oracle-map-sensed"),
    "oracle-map-gated": AgentSpec("oracle-map-gated", "oracle-map-gated"),
    "oracle-map-potential": AgentSpec("oracle-map-potential", "oracle-map-potential"),
    "observable": AgentSpec("observable", "observable"),
    "frontier": AgentSpec("frontier", "frontier"),
}
#: Baselines LEAPS is compared with in the relative-improvement plot.
BASELINES = ("random", "pure", "aug", "controller")
#: Named episode subsets: episodes per plan length (None: all).
SUBSETS = {"full": None, "quick": 20, "smoke": 2}
#: Most geodesic-distance bins of the success-vs-metres plot (about 10+ episodes each).
MAX_METRE_BINS = 8
CSV_FIELDS = ("episode", "house", "target", "plan_length", "geodesic", "success_step", "steps",
              "final_distance", "subtarget_changes")


@dataclasses.dataclass(frozen=True)
class EvalConfig:
    """What every row of an evaluation folder depends on.

    Attributes:
      dataset: dataset name or folder.
      split: split of the fixed episodes ("valid" or "test").
      horizon: the run horizon (the largest evaluated horizon).
      subpolicy: "local" (:class:`leaps_mj.planning.agents.LocalExpertPolicy`) or
        "learned" (``leaps_mj.learning.policies.load_default()``).
      prior: the LEAPS prior (see :func:`leaps_mj.planning.agents.load_model`).
      replan_every: LEAPS's N.
      seed: base seed of the episodes' agents.
      episodes: the fixed episode set (a key of
        :data:`leaps_mj.environment.episodes.EPISODE_SETS`: "plan_length", "hops" or "hops_large").
      policy_dir: with ``subpolicy="learned"``, a folder of sub-policy
        checkpoints (``<node>.pt``, ``shared.pt`` or ``goal.pt``) or the name of a
        shipped one (:data:`leaps_mj.learning.policy_folder.SHIPPED`); None: the
        shipped μ(θ).
      temperature: with ``subpolicy="learned"``, the sampling temperature of
        the sub-policies' actions (1: as trained; below 1 sharper).
    """

    dataset: str = dataset_lib.CANONICAL
    split: str = "test"
    horizon: int = 1000
    subpolicy: str = "local"
    prior: str = agents_lib.DEFAULT_PRIOR
    replan_every: int = 30
    seed: int = 0
    episodes: str = "plan_length"
    policy_dir: str | None = None
    temperature: float = 1.0

    def __post_init__(self):
        if isinstance(self.horizon, bool) or not isinstance(self.horizon, int) or self.horizon < 1:
            raise ValueError(f"horizon {self.horizon!r}: expected a positive integer")
        if self.subpolicy not in ("local", "learned"):
            raise ValueError(f"subpolicy {self.subpolicy!r}: expected 'local' or 'learned'")
        if self.episodes not in episodes_lib.EPISODE_SETS:
            raise ValueError(f"episodes {self.episodes!r}: expected one of {list(episodes_lib.EPISODE_SETS)}")
        if self.policy_dir is not None and self.subpolicy != "learned":
            raise ValueError(f"policy_dir {self.policy_dir!r} needs subpolicy 'learned', not {self.subpolicy!r}")
        if not self.temperature > 0:
            raise ValueError(f"temperature {self.temperature!r}: expected a positive number")
        if self.temperature != 1.0 and self.subpolicy != "learned":
            raise ValueError(f"temperature {self.temperature!r} needs subpolicy 'learned', not {self.subpolicy!r}")

    def to_json(self) -> dict:
        """The settings as ``config.json`` holds them.

        Fields added after the first results were written (:data:`LATER_FIELDS`)
        are left out at their defaults, so those folders stay valid and a
        rerun writes the same bytes.
        """
        out = dataclasses.asdict(self)
        for name, default in LATER_FIELDS.items():
            if out[name] == default:
                del out[name]
        return out


#: Fields of :class:`EvalConfig` newer than the committed results, with their defaults.
LATER_FIELDS = {"episodes": "plan_length", "policy_dir": None, "temperature": 1.0}


# -- workers -----------------------------------------------------------------

_WORKER: dict = {}


def _init_worker(config: EvalConfig, model: semantic.SemanticModel | None, record=None,
                 torch_threads: int | None = None) -> None:
    """Per-process state: the environment, the episodes, the LEAPS model, the learned sub-policy,
    and where to record episodes (``(folder, mode)`` or None).

    Pool workers run with one torch thread (``torch_threads=1``): several
    processes each spinning two OpenMP threads on two cores made the learned
    sub-policies' convolutions about ten times slower.
    """

    if torch_threads is not None:
        import torch

        torch.set_num_threads(torch_threads)

    _WORKER.clear()
    _WORKER["config"] = config
    _WORKER["env"] = roomnav.load(config.dataset, config.split, seed=config.seed, reward="sparse",
                                   horizon=config.horizon)
    _WORKER["specs"] = episodes_lib.load_split(config.dataset, config.split, config.episodes)
    _WORKER["model"] = model
    _WORKER["record"] = record
    _WORKER["recorders"] = {}
    _WORKER["subpolicy"] = None
    if config.subpolicy == "learned":
        from leaps_mj.learning import policy_folder

        _WORKER["subpolicy"] = policy_folder.load(config.policy_dir, config.temperature)


def _build_agent(spec: AgentSpec, seed: int):
    """The agent of one episode, in a worker."""
    config, env = _WORKER["config"], _WORKER["env"]
    kwargs = {}
    if spec.name == "leaps":
        if _WORKER["model"] is None:
            _WORKER["model"] = agents_lib.load_model(config.prior)
        model = _WORKER["model"]
        if spec.psi_obs is not None:
            model = semantic.SemanticModel(model.prior, *spec.psi_obs)
        kwargs = {"model": model, "rule": spec.rule, "replan_every": config.replan_every}
    if spec.name == "controller":
        from leaps_mj.learning import policy_folder

        kwargs = {"controller": policy_folder.controller_path(config.policy_dir)}
    subpolicy = _WORKER["subpolicy"]
    if spec.name == "aug":
        if "augmented" not in _WORKER:
            from leaps_mj.learning import policy_folder

            _WORKER["augmented"] = policy_folder.load_augmented(config.policy_dir)
        subpolicy = _WORKER["augmented"]
    if subpolicy is not None:
        subpolicy.seed(seed)  # the episode's own sampling stream, whatever ran before
    return registry.make_agent(spec.name, env, subpolicy=subpolicy, seed=seed, **kwargs)


def _observer(label: str):
    """This worker's MCAP episode recorder for an agent (None without ``--record``)."""
    if _WORKER["record"] is None:
        return None
    folder, mode = _WORKER["record"]
    recorders = _WORKER["recorders"]
    if label not in recorders:
        run_config = {**_WORKER["config"].to_json(), "agent": label}
        recorders[label] = record_lib.recorder_for_evaluation(folder / label, mode, seed=_WORKER["config"].seed,
                                                              run_config=run_config)
    return recorders[label]


def _run_chunk(job) -> tuple[AgentSpec, list[dict]]:
    """Runs one agent on a chunk of episode indices, in a worker."""
    spec, indices = job
    return spec, _episode_rows(spec, indices, _observer(spec.label))


def _episode_rows(spec: AgentSpec, indices, observer) -> list[dict]:
    """One agent's CSV rows of the episodes ``indices``, run in this worker with ``observer`` (or None)."""
    config, env, specs = _WORKER["config"], _WORKER["env"], _WORKER["specs"]
    if spec.bits in CLASSIFIER_BITS:
        key = f"env_{spec.bits}"
        if key not in _WORKER:
            from leaps_mj.learning import classifier

            _WORKER[key] = classifier.ClassifierBits(env, truth=CLASSIFIER_BITS[spec.bits])
        env = _WORKER[key]
    rows = []
    for i in indices:
        agent = _build_agent(spec, episodes_lib.episode_seed(config.seed, i))
        result = episodes_lib.run_episode(env, agent, specs[i], config.horizon, observer=observer)
        rows.append({"episode": i, **{k: result[k] for k in CSV_FIELDS if k != "episode"}})
    return rows


def run_observed(config: EvalConfig, spec: AgentSpec, indices, observer) -> list[dict]:
    """Runs one agent on the episodes ``indices`` in this process as :func:`run`'s workers do, with
    ``observer`` called at every step: for diagnostics that watch an evaluation's episodes
    (``tools/fig6_bits.py``), which check by the rows returned that they watched the same ones."""
    _init_worker(config, None)
    try:
        return _episode_rows(spec, indices, observer)
    finally:
        _WORKER.pop("env").close()


# -- result files --------------------------------------------------------------


def csv_path(out: pathlib.Path, label: str) -> pathlib.Path:
    return out / f"episodes_{label}.csv"


def read_rows(path: pathlib.Path) -> list[dict]:
    """Rows of a per-episode CSV with typed values ([] when the file does not exist)."""
    if not path.is_file():
        return []
    rows = []
    with open(path, newline="") as f:
        for r in csv.DictReader(f):
            rows.append({
                "episode": int(r["episode"]), "house": r["house"], "target": r["target"],
                "plan_length": int(r["plan_length"]) if r["plan_length"] else None,
                "geodesic": float(r["geodesic"]) if r["geodesic"] else None,
                "success_step": int(r["success_step"]) if r["success_step"] else None,
                "steps": int(r["steps"]), "final_distance": float(r["final_distance"]),
                "subtarget_changes": int(r["subtarget_changes"]),
            })
    return rows


def append_rows(path: pathlib.Path, rows: list[dict]) -> None:
    """Adds rows to a per-episode CSV by rewriting it atomically, sorted by episode.

    Sorting makes the file's bytes independent of the order in which worker
    chunks finish.
    """
    merged = sorted(read_rows(path) + list(rows), key=lambda r: r["episode"])
    buf = io.StringIO()
    writer = csv.DictWriter(buf, fieldnames=CSV_FIELDS, lineterminator="\n")
    writer.writeheader()
    for r in merged:
        writer.writerow({k: "" if r[k] is None else r[k] for k in CSV_FIELDS})
    files.write_atomic(path, buf.getvalue().encode())


def _check_config(out: pathlib.Path, config: EvalConfig) -> None:
    """Writes ``config.json``, or checks that the folder's rows were made with the same settings.

    Raises:
      ValueError: naming the differing settings.
    """
    path = out / "config.json"
    current = dataclasses.asdict(config)
    if path.is_file():
        saved = {**LATER_FIELDS, **json.loads(path.read_text())}
        diff = {k: (saved.get(k), v) for k, v in current.items() if saved.get(k) != v}
        if diff:
            raise ValueError(f"{str(out)!r} holds results made with other settings (saved, now): {diff}; "
                             "use another --out folder")
        return
    files.write_atomic(path, (json.dumps(config.to_json(), indent=1) + "\n").encode())


@contextlib.contextmanager
def chunk_results(where: backends.Backend, jobs: list, config: EvalConfig, model=None, record=None):
    """``(spec, rows)`` of every job ``(spec, episode indices)`` as it finishes, in this process or on
    ``where``'s workers: the part of :func:`run` that depends on the backend (also timed by
    ``benchmarks/ray_overhead.py``)."""
    if not where.in_process(len(jobs)):
        with backends.worker_pool(where, _init_worker, (config, model, record, 1), len(jobs)) as pool:
            yield pool.imap_unordered(_run_chunk, jobs)
        return
    if jobs:
        _init_worker(config, model, record)
    try:
        yield map(_run_chunk, jobs)
    finally:
        if "env" in _WORKER:
            _WORKER.pop("env").close()  # frees its GL context before interpreter exit


def run(config: EvalConfig, agent_specs, indices, out: pathlib.Path, workers: int | None = 1, chunk: int = 4,
        progress: bool = True, model: semantic.SemanticModel | None = None,
        record: tuple[pathlib.Path, str] | None = None, backend: str = "local",
        ray_address: str | None = None) -> dict[str, list[dict]]:
    """Runs every agent on the selected episodes, resuming from the CSVs in ``out``.

    The same jobs (chunks of one agent's episodes) run on either backend, and
    every finished chunk is merged into its agent's CSV sorted by episode, so
    the files' bytes depend neither on the backend nor on the workers.

    Args:
      config: shared settings (checked against ``out/config.json``).
      agent_specs: the :class:`AgentSpec` s to run.
      indices: episode indices (see :func:`select_episodes`).
      out: result folder.
      workers: processes or Ray actors (see :class:`leaps_mj.evaluation.backends.Backend`;
        1 locally: in this process).
      chunk: episodes per job; the CSV is rewritten after each.
      progress: show a tqdm bar.
      model: the LEAPS semantic model; None loads ``config.prior`` (then
        ``config.prior`` may name anything identifying the model, e.g. a hash).
      record: ``(folder, mode)`` to write MCAP records of the episodes run to
        ``folder/<agent>/`` (mode: all, failures or sample:K), or None. On a
        cluster the folder must be shared by the nodes.
      backend: "local" or "ray" (:mod:`leaps_mj.evaluation.backends`).
      ray_address: with ``backend="ray"``, the cluster to run on (None: a local Ray instance).

    Returns:
      label -> rows of the selected episodes, sorted by episode.
    """
    where = backends.Backend(backend, workers, ray_address)
    if chunk < 1:
        raise ValueError(f"chunk {chunk!r}: expected a positive integer")
    labels = [s.label for s in agent_specs]
    if len(set(labels)) != len(labels):
        raise ValueError(f"agent labels {labels} are not unique")
    out.mkdir(parents=True, exist_ok=True)
    _check_config(out, config)
    selected = set(indices)
    jobs = []
    for spec in agent_specs:
        done = {r["episode"] for r in read_rows(csv_path(out, spec.label))}
        todo = [i for i in indices if i not in done]
        jobs += [(spec, todo[k:k + chunk]) for k in range(0, len(todo), chunk)]
    with chunk_results(where, jobs, config, model, record) as results, \
            tqdm.tqdm(total=sum(len(j[1]) for j in jobs), desc="evaluate: episodes", disable=not progress) as bar:
        for spec, rows in results:
            append_rows(csv_path(out, spec.label), rows)
            bar.update(len(rows))
            bar.set_postfix_str(spec.label, refresh=False)
    table = {}
    for label in labels:
        rows = [r for r in read_rows(csv_path(out, label)) if r["episode"] in selected]
        table[label] = sorted({r["episode"]: r for r in rows}.values(), key=lambda r: r["episode"])
    return table


# -- statistics ------------------------------------------------------------------


def metre_bins(distances) -> np.ndarray:
    """Edges (whole metres) of up to :data:`MAX_METRE_BINS` bins holding about equal numbers of episodes."""
    d = np.asarray([v for v in distances if v is not None], dtype=float)
    if d.size == 0:
        return np.array([0.0, 1.0])
    k = int(np.clip(d.size // 10, 1, MAX_METRE_BINS))
    edges = np.unique(np.round(np.quantile(d, np.linspace(0.0, 1.0, k + 1))))
    edges[0], edges[-1] = np.floor(d.min()), np.ceil(d.max()) + 1.0
    return np.unique(edges)


def summarize(table: dict[str, list[dict]], horizons) -> dict:
    """Success rates per agent and horizon: overall, by plan length, by distance bin.

    Distance bins (:func:`metre_bins`) are shared by all agents.

    Returns:
      ``{label: {str(H): {"all": rate, "plan_length": {L: rate}, "metres": {"lo-hi": rate}}}}``.
    """
    edges = metre_bins({r["episode"]: r["geodesic"] for rows in table.values() for r in rows}.values())
    names = [f"{lo:g}-{hi:g}" for lo, hi in zip(edges[:-1], edges[1:])]
    out = {}
    for label, rows in table.items():
        lengths = np.array([r["plan_length"] or 0 for r in rows])
        dist = np.array([r["geodesic"] if r["geodesic"] is not None else np.nan for r in rows])
        bins = np.digitize(dist, edges[1:-1])
        out[label] = {}
        for h in horizons:
            s = stats.success_at(rows, h)
            out[label][str(h)] = {
                "all": stats.rate(s),
                "plan_length": {int(L): stats.rate(s[lengths == L]) for L in sorted(set(lengths.tolist()))},
                "metres": {names[b]: stats.rate(s[np.isfinite(dist) & (bins == b)]) for b in range(len(names))},
            }
    return out


def relative_improvement(summary: dict, leaps: str, baseline: str, horizon: int) -> dict:
    """(LEAPS - baseline) / baseline success per plan length and overall (nan where baseline is 0)."""
    a, b = summary[leaps][str(horizon)], summary[baseline][str(horizon)]
    out = {}
    for key, ra, rb in [("all", a["all"], b["all"])] + [
            (L, a["plan_length"][L], b["plan_length"].get(L)) for L in a["plan_length"]]:
        out[key] = (ra["rate"] - rb["rate"]) / rb["rate"] if rb and rb["rate"] > 0 else math.nan
    return out


# -- report -------------------------------------------------------------------------


def compared(labels) -> tuple[list[str], list[str]]:
    """The LEAPS agents among ``labels`` (``leaps*``) and the baselines they are compared with."""
    return ([label for label in labels if label.startswith("leaps")],
            [label for label in labels if label in BASELINES])


def _paired_cell(t: dict) -> str:
    return f"{100 * (t['a'] - t['b']) / t['n']:+.1f} ({t['a_only']}/{t['b_only']}, p = {t['p']:.2g})"


def _cell(r: dict) -> str:
    return f"{100 * r['rate']:.1f}% [{100 * r['low']:.1f}, {100 * r['high']:.1f}] (n={r['n']})"


def markdown(summary: dict, horizons, config: EvalConfig, n_episodes: int, paired: dict | None = None) -> str:
    """The results as markdown tables, with the paired tests of :func:`stats.paired_comparisons` when given."""
    labels = list(summary)
    lines = [
        f"# RoomNav evaluation: {config.dataset} / {config.split}",
        "",
        f"{n_episodes} fixed episodes; sub-policy `{config.subpolicy}`; LEAPS prior `{config.prior}`, "
        f"N = {config.replan_every}; seed {config.seed}. Success rate with a 95% Wilson interval. "
        f"Each episode ran once at H = {config.horizon}; success at a smaller H counts successes by "
        "that step (exact: no agent's behaviour depends on H).",
        "",
        "| agent | " + " | ".join(f"H = {h}" for h in horizons) + " |",
        "|---|" + "---|" * len(horizons),
    ]
    for label in labels:
        lines.append(f"| {label} | " + " | ".join(_cell(summary[label][str(h)]["all"]) for h in horizons) + " |")
    lengths = sorted({L for label in labels for L in summary[label][str(horizons[0])]["plan_length"]})
    for h in horizons:
        lines += ["", f"## By optimal plan length, H = {h}", "",
                  "| agent | " + " | ".join(f"L = {L}" for L in lengths) + " |",
                  "|---|" + "---|" * len(lengths)]
        for label in labels:
            per = summary[label][str(h)]["plan_length"]
            lines.append(f"| {label} | " + " | ".join(_cell(per[L]) if L in per else "-" for L in lengths) + " |")
    leaps, bases = compared(labels)
    if leaps and bases:
        lines += ["", "## Relative improvement of LEAPS, (LEAPS - baseline) / baseline", "",
                  "| LEAPS | baseline | " + " | ".join(f"H = {h}" for h in horizons) + " |",
                  "|---|---|" + "---|" * len(horizons)]
        for a in leaps:
            for b in bases:
                cells = [relative_improvement(summary, a, b, h)["all"] for h in horizons]
                lines.append(f"| {a} | {b} | " + " | ".join(
                    "n/a (baseline 0)" if math.isnan(c) else f"{100 * c:+.0f}%" for c in cells) + " |")
    for a, per_base in (paired or {}).items():
        for b, per_h in per_base.items():
            lengths = sorted({L for t in per_h.values() for L in t["plan_length"]})
            lines += ["", f"## Paired: {a} against {b} on the same episodes",
                      "", "Success difference in points (episodes only LEAPS / only the baseline solved, "
                      "two-sided exact McNemar p).", "",
                      "| H | all | " + " | ".join(f"L = {L}" for L in lengths) + " |",
                      "|---|---|" + "---|" * len(lengths)]
            for h in horizons:
                t = per_h[str(h)]
                lines.append(f"| {h} | {_paired_cell(t['all'])} | " + " | ".join(
                    _paired_cell(t["plan_length"][L]) if L in t["plan_length"] else "-" for L in lengths) + " |")
    return "\n".join(lines) + "\n"


def plot(summary: dict, horizons, out: pathlib.Path) -> list[pathlib.Path]:
    """Writes the success-vs-plan-length, success-vs-metres and relative-improvement figures."""
    import matplotlib.pyplot as plt

    from leaps_mj.world import topdown

    labels = list(summary)
    paths = []
    for key, xlabel, name in (("plan_length", "optimal plan length (room hops)", "success_vs_plan_length.png"),
                              ("metres", "geodesic distance to target (m)", "success_vs_metres.png")):
        fig, axes = plt.subplots(1, len(horizons), figsize=(4.6 * len(horizons), 3.8), sharey=True, squeeze=False)
        for ax, h in zip(axes[0], horizons):
            for k, label in enumerate(labels):
                per = summary[label][str(h)][key]
                keys = [b for b in per if per[b]["n"] > 0]
                x = np.array([np.mean([float(v) for v in b.split("-")]) if key == "metres" else b for b in keys])
                x = x + (k - (len(labels) - 1) / 2) * (0.06 if key == "plan_length" else 0.15)
                y = np.array([per[b]["rate"] for b in keys])
                err = np.array([[per[b]["rate"] - per[b]["low"] for b in keys],
                                [per[b]["high"] - per[b]["rate"] for b in keys]]).reshape(2, -1)
                ax.errorbar(x, y, yerr=err, marker="o", ms=4, capsize=3, label=label)
            ax.set_title(f"H = {h}")
            ax.set_xlabel(xlabel)
            ax.set_ylim(-0.02, 1.02)
            ax.grid(alpha=0.3)
            if key == "plan_length":
                ax.set_xticks(sorted({L for label in labels for L in summary[label][str(h)]["plan_length"]}))
        axes[0][0].set_ylabel("success rate (95% Wilson CI)")
        axes[0][-1].legend(fontsize=8)
        topdown.save_figure(fig, out / name)
        paths.append(out / name)
    leaps, bases = compared(labels)
    if leaps and bases:
        # One row per baseline: improvements over random dwarf those over pure.
        fig, axes = plt.subplots(len(bases), len(horizons), figsize=(4.6 * len(horizons), 3.4 * len(bases)),
                                 sharey="row", squeeze=False)
        for row, b in zip(axes, bases):
            for ax, h in zip(row, horizons):
                for a in leaps:
                    imp = relative_improvement(summary, a, b, h)
                    lengths = [L for L in imp if L != "all"]
                    ax.plot(lengths, [100 * imp[L] for L in lengths], marker="o", label=a)
                ax.axhline(0, color="black", lw=0.8)
                ax.set_xticks(lengths)
                ax.set_title(f"over {b}, H = {h}")
                ax.grid(alpha=0.3)
            row[0].set_ylabel(f"(LEAPS - {b}) / {b} (%)")
            row[-1].legend(fontsize=8)
        for ax in axes[-1]:
            ax.set_xlabel("optimal plan length (room hops)")
        topdown.save_figure(fig, out / "relative_improvement.png")
        paths.append(out / "relative_improvement.png")
    return paths


def report(table: dict[str, list[dict]], horizons, config: EvalConfig, out: pathlib.Path) -> dict:
    """Writes ``results.md``, ``summary.json`` and the plots; returns the summary."""
    summary = summarize(table, horizons)
    paired = stats.paired_comparisons(table, horizons, *compared(table))
    n = max((len(rows) for rows in table.values()), default=0)
    files.write_atomic(out / "results.md", markdown(summary, horizons, config, n, paired).encode())
    files.write_atomic(out / "summary.json", (json.dumps(
        {"config": config.to_json(), "horizons": list(horizons), "episodes": n, "success": summary,
         "paired": paired}, indent=1) + "\n").encode())
    plot(summary, horizons, out)
    return summary


def command_line_policy_dir(subpolicy: str, policy_dir: str | None) -> str | None:
    """``EvalConfig.policy_dir`` for the command line's choice: the shipped map-goal folder's name by default with
    learned sub-policies; the shipped μ(θ) (name ``cpu``) as None, as result folders made before it was named
    record it."""
    if subpolicy != "learned":
        return policy_dir
    from leaps_mj.learning import policy_folder

    policy_dir = policy_folder.DEFAULT if policy_dir is None else policy_dir
    return None if policy_folder.resolve(policy_dir).resolve() == policy_folder.SHIPPED["cpu"].resolve() else policy_dir


def main(argv=None) -> int:
    p = argparse.ArgumentParser(prog="python -m leaps_mj.evaluate", description=__doc__,
                                formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--agent", nargs="+", choices=list(AGENTS), default=["random", "pure", "leaps"])
    p.add_argument("--dataset", default=dataset_lib.CANONICAL)
    p.add_argument("--split", default="test", choices=["valid", "test"])
    p.add_argument("--horizon", nargs="+", type=int, default=[300, 500, 1000])
    p.add_argument("--out", type=pathlib.Path, required=True, help="result folder (resumable)")
    p.add_argument("--subpolicy", choices=["local", "learned"], default="learned",
                   help="learned (default): the sub-policies of --policy-dir; local: the privileged local expert")
    p.add_argument("--prior", default=None,
                   help="LEAPS prior: a shipped name (cpu, cpu_learned), 'reference', or a JSON path (default: "
                        f"by sub-policy, {agents_lib.SUBPOLICY_PRIORS})")
    p.add_argument("--replan-every", type=int, help=f"LEAPS's N (default: {agents_lib.SUBPOLICY_REPLAN_EVERY})")
    p.add_argument("--temperature", type=float, default=1.0,
                   help="sampling temperature of the learned sub-policies' actions (1: as trained)")
    p.add_argument("--policy-dir", default=None,
                   help="with --subpolicy learned: a folder of sub-policy checkpoints (<node>.pt, shared.pt, or a "
                        "map-goal network goal.pt), or a shipped one by name: goal_cpu (the map-goal sub-policy, "
                        "the default) or cpu (the per-target CNN+LSTM networks μ(θ))")
    p.add_argument("--subset", choices=list(SUBSETS), default="full",
                   help=f"episodes per plan length: {SUBSETS}")
    p.add_argument("--episodes-per-length", type=int, default=None, help="overrides --subset")
    p.add_argument("--limit", type=int, default=None, help="only the first N selected episodes")
    backends.add_arguments(p)
    p.add_argument("--seed", type=int, default=0)
    p.add_argument("--no-progress", action="store_true")
    p.add_argument("--record", type=pathlib.Path, metavar="DIR",
                   help="write MCAP episode records to DIR/<agent>/ (see docs/records.md)")
    p.add_argument("--record-mode", default="failures", help="all, failures or sample:K (default: failures)")
    args = p.parse_args(argv)
    horizons = sorted(set(args.horizon))
    if horizons[0] < 1:
        p.error(f"--horizon {args.horizon}: expected positive integers")
    where = backends.from_arguments(p, args)
    args.policy_dir = command_line_policy_dir(args.subpolicy, args.policy_dir)
    args.prior, args.replan_every = agents_lib.subpolicy_defaults(args.subpolicy, args.prior, args.replan_every)
    try:
        config = EvalConfig(dataset=args.dataset, split=args.split, horizon=horizons[-1], subpolicy=args.subpolicy,
                            prior=args.prior, replan_every=args.replan_every, seed=args.seed,
                            temperature=args.temperature, policy_dir=args.policy_dir)
        if "leaps" in " ".join(args.agent):
            agents_lib.load_model(args.prior)  # fail now, not in a worker
        if args.record:
            record_lib.parse_mode(args.record_mode)  # fail now, not in a worker
        specs = episodes_lib.load_split(args.dataset, args.split)
        per_length = args.episodes_per_length or SUBSETS[args.subset]
        indices = episodes_lib.select_episodes(specs, per_length, args.limit, args.seed)
        table = run(config, [AGENTS[a] for a in args.agent], indices, args.out, workers=where.workers,
                    progress=not args.no_progress, record=(args.record, args.record_mode) if args.record else None,
                    backend=where.name, ray_address=where.address)
    except ValueError as e:
        print(f"error: {e}", file=sys.stderr)
        return 2
    report(table, horizons, config, args.out)
    print((args.out / "results.md").read_text())
    return 0


if __name__ == "__main__":
    sys.exit(main())
