"""Grid-search the semantic model's observation noise on the validation episodes.

``python -m leaps_mj.train obs-noise --preset cpu --out runs/prior_cpu``

The paper sets the noise of the semantic observations, P(y=1 | z=0) =
psi_obs0 and P(y=0 | z=1) = psi_obs1, to (0.001, 0.15). Here every pair of a
small grid around those values is scored by the success rate of the LEAPS
agent (paper observation rule) on the fixed validation episodes, with the
local-expert sub-policy (``--subpolicy learned`` for the learned ones). All
grid points run the same episodes with the same seeds, so they differ only
in the noise. The best pair (ties go to the paper's values, then to the
earlier grid point) is written into ``<out>/prior.json`` with the learned
prior, which is the file to ship as ``leaps_mj/data/prior_<preset>.json``.

The prior is read from ``--prior``, by default ``<out>/prior.json`` (as left
by ``python -m leaps_mj.train prior --out <out>``) or else the shipped
default. Episode results are kept under ``<out>/obs_noise/<prior hash>/`` and
reused by a later run with the same prior (resumable).
"""

from __future__ import annotations

import argparse
import dataclasses
import hashlib
import itertools
import pathlib
import sys

import numpy as np

from leaps_mj.environment import episodes as episodes_lib
from leaps_mj.evaluation import harness as evaluate
from leaps_mj.planning import agents as agents_lib
from leaps_mj.planning import semantic
from leaps_mj.world import dataset as dataset_lib

PAPER = (semantic.PAPER_PSI_OBS0, semantic.PAPER_PSI_OBS1)


@dataclasses.dataclass(frozen=True)
class TuneConfig:
    """Settings of the observation-noise search.

    Attributes:
      dataset: dataset name or folder.
      split: split of the fixed episodes scored on.
      psi_obs0: grid of false-positive rates.
      psi_obs1: grid of false-negative rates.
      episodes_per_length: validation episodes per plan length (None: all).
      horizon: steps per episode.
      seed: seed of the episode subset and the agents.
    """

    dataset: str = dataset_lib.CANONICAL
    split: str = "valid"
    psi_obs0: tuple[float, ...] = (0.001, 0.01, 0.05)
    psi_obs1: tuple[float, ...] = (0.05, 0.15, 0.3)
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

    def grid(self) -> list[tuple[float, float]]:
        return list(itertools.product(self.psi_obs0, self.psi_obs1))


PRESETS = {
    "tiny": TuneConfig(psi_obs0=(0.001, 0.05), psi_obs1=(0.15,), episodes_per_length=1, horizon=100),
    "cpu": TuneConfig(episodes_per_length=25, horizon=500),
    "paper": TuneConfig(episodes_per_length=None, horizon=1000),
}


def label(psi: tuple[float, float]) -> str:
    """File-safe agent label of one grid point."""
    return f"leaps-psi{psi[0]:g}-{psi[1]:g}"


def choose(scores: dict[tuple[float, float], float]) -> tuple[float, float]:
    """The grid point of highest success; ties to the paper's values, then to grid order."""
    best = max(scores.values())
    tied = [psi for psi, s in scores.items() if np.isclose(s, best)]
    return PAPER if PAPER in tied else tied[0]


def tune(config: TuneConfig, prior: pathlib.Path, out: pathlib.Path, subpolicy: str = "local",
         workers: int = 1, progress: bool = True) -> tuple[tuple[float, float], dict]:
    """Runs the grid and returns (chosen (psi_obs0, psi_obs1), summary per grid point)."""
    model = semantic.SemanticModel.from_json(prior)
    digest = hashlib.sha256(np.ascontiguousarray(model.prior).tobytes()).hexdigest()[:12]
    # Results depend on the prior matrix, not on the file's path or the noise stored with it.
    eval_config = evaluate.EvalConfig(dataset=config.dataset, split=config.split, horizon=config.horizon,
                                      subpolicy=subpolicy, prior=f"sha256:{digest}", seed=config.seed)
    specs = episodes_lib.load_split(config.dataset, config.split)
    indices = episodes_lib.select_episodes(specs, config.episodes_per_length, seed=config.seed)
    grid = config.grid()
    agent_specs = [evaluate.AgentSpec(label(psi), "leaps", rule="paper", psi_obs=psi) for psi in grid]
    table = evaluate.run(eval_config, agent_specs, indices, out / "obs_noise" / digest, workers=workers,
                         progress=progress, model=model)
    summary = evaluate.summarize(table, [config.horizon])
    per_point = {psi: summary[label(psi)][str(config.horizon)]["all"] for psi in grid}
    return choose({psi: r["rate"] for psi, r in per_point.items()}), per_point


def _floats(text: str) -> tuple[float, ...]:
    try:
        return tuple(float(v) for v in text.split(","))
    except ValueError:
        raise argparse.ArgumentTypeError(f"{text!r}: expected comma-separated numbers") from None


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
    p.add_argument("--workers", type=int, default=1)
    p.add_argument("--seed", type=int, default=None)
    for name in ("psi_obs0", "psi_obs1"):
        p.add_argument(f"--{name.replace('_', '-')}", type=_floats, default=None,
                       help=f"grid of {name}, comma-separated (default: the preset's)")
    p.add_argument("--episodes-per-length", type=int, default=None,
                   help="validation episodes per plan length (default: preset's)")
    args = p.parse_args(argv)
    overrides = {k: getattr(args, k) for k in ("dataset", "seed", "psi_obs0", "psi_obs1", "episodes_per_length")
                 if getattr(args, k) is not None}
    try:
        config = dataclasses.replace(PRESETS[args.preset], **overrides)
    except ValueError as e:
        p.error(str(e))
    out = args.out or pathlib.Path("runs") / f"prior_{args.preset}"
    prior = args.prior
    if prior is None:
        prior = out / "prior.json" if (out / "prior.json").is_file() else agents_lib.prior_path(
            agents_lib.DEFAULT_PRIOR)
    print(f"obs-noise: {config}; prior {prior}; sub-policy {args.subpolicy}", flush=True)
    try:
        chosen, per_point = tune(config, prior, out, args.subpolicy, args.workers)
    except ValueError as e:
        print(f"error: {e}", file=sys.stderr)
        return 2
    lines = [f"| psi_obs0 | psi_obs1 | LEAPS success at H = {config.horizon} (95% Wilson CI) |", "|---|---|---|"]
    for psi, r in per_point.items():
        mark = " **chosen**" if psi == chosen else ""
        lines.append(f"| {psi[0]:g} | {psi[1]:g} | {100 * r['rate']:.1f}% [{100 * r['low']:.1f}, "
                     f"{100 * r['high']:.1f}] (n={r['n']}){mark} |")
    table = "\n".join(lines) + "\n"
    dataset_lib.write_atomic(out / "obs_noise.md", table.encode())
    model = semantic.SemanticModel(semantic.SemanticModel.from_json(prior).prior, *chosen)
    model.to_json(out / "prior.json")
    print(table)
    print(f"chosen psi_obs0 = {chosen[0]:g}, psi_obs1 = {chosen[1]:g}; wrote {out / 'prior.json'} "
          f"and {out / 'obs_noise.md'}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
