"""``python -m leaps_mj.replay``: summarise and render MCAP records (:mod:`leaps_mj.records.replay`).

Kept at the package top so that the command users type stays the same; the
code lives in :mod:`leaps_mj.records`.
"""

import sys

from leaps_mj.records.replay import main

if __name__ == "__main__":
    sys.exit(main())
