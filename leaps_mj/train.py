"""Training entry point: ``python -m leaps_mj.train <trainer> [options]``.

Trainers (each a single-file module with its own ``main(argv)``, cleanrl style):

  prior       learn the room-connectivity prior by random exploration (leaps_mj.learning.train_prior)
  obs-noise   grid-search the observation noise on the validation episodes (leaps_mj.evaluation.tune_obs_noise)
  policy      train per-target CNN+LSTM sub-policies (leaps_mj.learning.train_policy)
  classifier  train the CNN room-type classifier (leaps_mj.learning.train_classifier)
  controller  train the LSTM controller baseline (leaps_mj.learning.train_controller)
  goal        train the map-goal sub-policy's network by DAgger rounds (leaps_mj.learning.train_goal)
  all         reproduce the shipped checkpoints: prior, policy (every target), obs-noise

``python -m leaps_mj.train <trainer> --help`` lists a trainer's options.
"""

from __future__ import annotations

import importlib
import sys

TRAINERS = {
    "prior": "leaps_mj.learning.train_prior",
    "obs-noise": "leaps_mj.evaluation.tune_obs_noise",
    "policy": "leaps_mj.learning.train_policy",
    "classifier": "leaps_mj.learning.train_classifier",
    "controller": "leaps_mj.learning.train_controller",
    "goal": "leaps_mj.learning.train_goal",
}
#: What ``all`` runs, in order (each trainer resumes from its checkpoints).
ALL = ("prior", "policy", "obs-noise")


def main(argv=None) -> int:
    argv = list(sys.argv[1:] if argv is None else argv)
    if not argv or argv[0] in ("-h", "--help"):
        print(__doc__)
        return 0 if argv else 2
    name, rest = argv[0], argv[1:]
    if name == "all":
        for step in ALL:
            print(f"== python -m leaps_mj.train {step} {' '.join(rest)}", flush=True)
            code = _run(step, rest)
            if code:
                return code
        return 0
    if name not in TRAINERS:
        print(f"unknown trainer {name!r}; expected one of {sorted(TRAINERS) + ['all']}", file=sys.stderr)
        return 2
    return _run(name, rest)


def _run(name: str, argv: list[str]) -> int:
    """Runs a trainer's ``main``; a missing trainer module or a bad option value (ValueError) is one line
    on stderr and exit code 2."""
    try:
        module = importlib.import_module(TRAINERS[name])
    except ModuleNotFoundError as e:
        print(f"trainer {name!r} is not available: {e}", file=sys.stderr)
        return 2
    try:
        return module.main(argv) or 0
    except ValueError as e:
        print(f"error: {e}", file=sys.stderr)
        return 2


if __name__ == "__main__":
    sys.exit(main())
