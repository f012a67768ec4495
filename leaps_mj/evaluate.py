"""``python -m leaps_mj.evaluate``: the evaluation command (:mod:`leaps_mj.evaluation.harness`).

Kept at the package top so that the command users type stays the same; the
code lives in :mod:`leaps_mj.evaluation`.
"""

import sys

from leaps_mj.evaluation.harness import main

if __name__ == "__main__":
    sys.exit(main())
