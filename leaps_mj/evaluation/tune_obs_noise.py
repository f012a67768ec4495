"""Grid-search the semantic model's observation noise (and LEAPS's N) on the validation episodes.

``python -m leaps_mj.train obs-noise --preset cpu --out runs/prior_cpu``

The paper sets the noise of the semantic observations, P(y=1 | z=0) =
psi_obs0 and P(y=0 | z=1) = psi_obs1, to (0.001, 0.15), and hands the
sub-policy N = 30 steps between replans. Both reflect how reliable the
sub-policies are, so the paper tunes them on validation houses. Here every
point of a small grid (psi_obs0 x psi_obs1 x N) is scored by the success rate
of the LEAPS agent (``--rule``: the paper's observation rule by default) on
the fixed validation episodes, with the local-expert sub-policy
(``--subpolicy learned`` for the learned ones, ``--policy-dir`` for a folder
other than the shipped one). All grid points run the same episodes with the
same seeds, so they differ only in the noise and N. The best point (ties go
to the paper's values, then to the earlier grid point) is written into
``<out>/prior.json`` with the learned prior, which is the file to ship as
``leaps_mj/data/prior_<preset>.json`` (or beside a sub-policy folder's
checkpoints), and into ``<out>/obs_noise.json`` with its N.

The prior is read from ``--prior``, by default ``<out>/prior.json`` (as left
by ``python -m leaps_mj.train prior --out <out>``) or else the shipped
default. Episode results are kept under ``<out>/obs_noise/<prior hash>/N<N>/``
and reused by a later run with the same prior (resumable).
"""

from __future__ import annotations

import argparse
import dataclasses
import hashlib
import itertools
import json
import pathlib
import sys

import numpy as np

from leaps_mj.environment import episodes as episodes_lib
from leaps_mj.evaluation import harness as evaluate
from leaps_mj.planning import agents as agents_lib
from leaps_mj.planning import semantic
from leaps_mj.world import dataset as dataset_lib
from leaps_mj.world import files

PAPER = (semantic.PAPER_PSI_OBS0, semantic.PAPER_PSI_OBS1)
#: The paper's N, steps between replans.
PAPER_N = 30


@dataclasses.dataclass(frozen=True)
class TuneConfig:
    """Settings of the observation-noise search.

    Attributes:
      dataset: dataset name or folder.
      split: split of the fixed episodes scored on.
      psi_obs0: grid of false-positive rates.
      psi_obs1: grid of false-negative rates.
      replan_every: grid of N, steps between replans.
      rule: LEAPS's observation rule ("paper" or "release").
      episodes_per_length: validation episodes per plan length (None: all).
      horizon: steps per episode.
      seed: seed of the episode subset and the agents.
    """

    dataset: str = dataset_lib.CANONICAL
    split: str = "valid"
    psi_obs0: tuple[float, ...] = (0.001, 0.01, 0.05)
    psi_obs1: tuple[float, ...] = (0.05, 0.15, 0.3)
    replan_every: tuple[int, ...] = (PAPER_N,)
    rule: str = "paper"
    episodes_per_length: int | None = 10
    horizon: int = 500
    seed: int = 0

    def __post_init__(self):
        if self.episodes_per_length is not None and (isinstance(self.episodes_per_length, bool)
                                                     or not isinstance(self.episodes_per_length, int)
                                                     or self.episodes_per_length < 1):
            raise ValueError(f"episodes_per_length {self.episodes_per_length!r}: expected a positive integer or None")
        for name in ("psi_obs0", "psi_obs1"):
            values = getattr(self, name)
            if not values or any(not 0.0 <= v < 1.0 for v in values):
                raise ValueError(f"{name} grid {values!r}: expected probabilities in [0, 1)")
        if not self.replan_every or any(isinstance(n, bool) or not isinstance(n, int) or n < 1
                                        for n in self.replan_every):
            raise ValueError(f"replan_every grid {self.replan_every!r}: expected positive integers")
        if self.rule not in agents_lib.RULES:
            raise ValueError(f"rule {self.rule!r}: expected one of {list(agents_lib.RULES)}")

    def grid(self) -> list[tuple[float, float, int]]:
        """Every (psi_obs0, psi_obs1, N) point, N slowest."""
        return [(psi0, psi1, n) for n, psi0, psi1 in itertools.product(self.replan_every, self.psi_obs0,
                                                                       self.psi_obs1)]


PRESETS = {
    "tiny": TuneConfig(psi_obs0=(0.001, 0.05), psi_obs1=(0.15,), episodes_per_length=1, horizon=100),
    "cpu": TuneConfig(episodes_per_length=25, horizon=500),
    "paper": TuneConfig(episodes_per_length=None, horizon=1000),
}


def label(psi: tuple[float, float], rule: str = "paper") -> str:
    """File-safe agent label of one noise pair (the rule named unless it is the paper's)."""
    name = "leaps" if rule == "paper" else f"leaps-{rule}"
    return f"{name}-psi{psi[0]:g}-{psi[1]:g}"


def choose(scores: dict[tuple[float, float, int], float]) -> tuple[float, float, int]:
    """The (psi_obs0, psi_obs1, N) of highest success; ties to the paper's values, then to grid order."""
    best = max(scores.values())
    tied = [point for point, s in scores.items() if np.isclose(s, best)]
    paper = (*PAPER, PAPER_N)
    return paper if paper in tied else tied[0]


def tune(config: TuneConfig, prior: pathlib.Path, out: pathlib.Path, subpolicy: str = "local",
         workers: int = 1, progress: bool = True,
         policy_dir: str | None = None) -> tuple[tuple[float, float, int], dict]:
    """Runs the grid and returns (chosen (psi_obs0, psi_obs1, N), success summary per grid point)."""
    model = semantic.SemanticModel.from_json(prior)
    digest = hashlib.sha256(np.ascontiguousarray(model.prior).tobytes()).hexdigest()[:12]
    specs = episodes_lib.load_split(config.dataset, config.split)
    indices = episodes_lib.select_episodes(specs, config.episodes_per_length, seed=config.seed)
    pairs = list(itertools.product(config.psi_obs0, config.psi_obs1))
    agent_specs = [evaluate.AgentSpec(label(psi, config.rule), "leaps", rule=config.rule, psi_obs=psi)
                   for psi in pairs]
    per_point = {}
    for n in config.replan_every:
        # Results depend on the prior matrix, not on the file's path or the noise stored with it.
        eval_config = evaluate.EvalConfig(dataset=config.dataset, split=config.split, horizon=config.horizon,
                                          subpolicy=subpolicy, prior=f"sha256:{digest}", replan_every=n,
                                          seed=config.seed, policy_dir=policy_dir)
        table = evaluate.run(eval_config, agent_specs, indices, out / "obs_noise" / digest / f"N{n}",
                             workers=workers, progress=progress, model=model)
        summary = evaluate.summarize(table, [config.horizon])
        per_point.update({(*psi, n): summary[label(psi, config.rule)][str(config.horizon)]["all"]
                          for psi in pairs})  # in grid order: N slowest
    return choose({point: r["rate"] for point, r in per_point.items()}), per_point


def _grid(cast, what: str):
    """An argparse type reading a comma-separated grid of ``cast`` values (``what`` names them in errors)."""
    def parse(text: str) -> tuple:
        try:
            return tuple(cast(v) for v in text.split(","))
        except ValueError:
            raise argparse.ArgumentTypeError(f"{text!r}: expected comma-separated {what}") from None
    return parse


_floats, _ints = _grid(float, "numbers"), _grid(int, "integers")


def main(argv=None) -> int:
    p = argparse.ArgumentParser(prog="python -m leaps_mj.train obs-noise", description=__doc__,
                                formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--preset", choices=sorted(PRESETS), default="cpu",
                   help="tiny: 2 points x 1 episode per plan length; cpu: 3x3 x 25, H=500; paper: 3x3 x all, H=1000")
    p.add_argument("--out", type=pathlib.Path, default=None, help="output folder (default runs/prior_<preset>)")
    p.add_argument("--prior", type=pathlib.Path, default=None,
                   help="prior JSON (default <out>/prior.json, else the shipped default)")
    p.add_argument("--dataset", default=None)
    p.add_argument("--subpolicy", choices=["local", "learned"], default="local")
    p.add_argument("--policy-dir", default=None,
                   help="with --subpolicy learned: a folder of sub-policy checkpoints instead of the shipped ones")
    p.add_argument("--rule", choices=list(agents_lib.RULES), default=None,
                   help="LEAPS's observation rule (default: the preset's, paper)")
    p.add_argument("--replan-every", type=_ints, default=None,
                   help="grid of N, comma-separated (default: the preset's, 30)")
    p.add_argument("--workers", type=int, default=1)
    p.add_argument("--seed", type=int, default=None)
    for name in ("psi_obs0", "psi_obs1"):
        p.add_argument(f"--{name.replace('_', '-')}", type=_floats, default=None,
                       help=f"grid of {name}, comma-separated (default: the preset's)")
    p.add_argument("--episodes-per-length", type=int, default=None,
                   help="validation episodes per plan length (default: preset's)")
    args = p.parse_args(argv)
    if args.policy_dir is not None and args.subpolicy != "learned":
        p.error(f"--policy-dir {args.policy_dir!r} needs --subpolicy learned, not {args.subpolicy!r}")
    overrides = {k: getattr(args, k) for k in ("dataset", "seed", "psi_obs0", "psi_obs1", "replan_every", "rule",
                                               "episodes_per_length") if getattr(args, k) is not None}
    try:
        config = dataclasses.replace(PRESETS[args.preset], **overrides)
    except ValueError as e:
        p.error(str(e))
    out = args.out or pathlib.Path("runs") / f"prior_{args.preset}"
    prior = args.prior
    if prior is None:
        prior = out / "prior.json" if (out / "prior.json").is_file() else agents_lib.prior_path(
            agents_lib.DEFAULT_PRIOR)
    print(f"obs-noise: {config}; prior {prior}; sub-policy {args.subpolicy} {args.policy_dir or ''}", flush=True)
    try:
        chosen, per_point = tune(config, prior, out, args.subpolicy, args.workers, policy_dir=args.policy_dir)
    except ValueError as e:
        print(f"error: {e}", file=sys.stderr)
        return 2
    lines = [f"| psi_obs0 | psi_obs1 | N | LEAPS ({config.rule} rule) success at H = {config.horizon} "
             "(95% Wilson CI) |", "|---|---|---|---|"]
    for point, r in per_point.items():
        mark = " **chosen**" if point == chosen else ""
        lines.append(f"| {point[0]:g} | {point[1]:g} | {point[2]} | {100 * r['rate']:.1f}% [{100 * r['low']:.1f}, "
                     f"{100 * r['high']:.1f}] (n={r['n']}){mark} |")
    table = "\n".join(lines) + "\n"
    files.write_atomic(out / "obs_noise.md", table.encode())
    files.write_atomic(out / "obs_noise.json", (json.dumps(
        {"psi_obs0": chosen[0], "psi_obs1": chosen[1], "replan_every": chosen[2], "rule": config.rule,
         "subpolicy": args.subpolicy, "policy_dir": args.policy_dir}, indent=1) + "\n").encode())
    model = semantic.SemanticModel(semantic.SemanticModel.from_json(prior).prior, *chosen[:2])
    model.to_json(out / "prior.json")
    print(table)
    print(f"chosen psi_obs0 = {chosen[0]:g}, psi_obs1 = {chosen[1]:g}, N = {chosen[2]}; wrote {out / 'prior.json'}, "
          f"{out / 'obs_noise.json'} and {out / 'obs_noise.md'}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
