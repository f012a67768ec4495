"""RoomNav-MJ and LEAPS: semantic multi-room navigation in MuJoCo.

Importing the package settles MuJoCo's off-screen OpenGL backend before
MuJoCo is imported (:mod:`leaps_mj.environment.gl_backend`: EGL when it
starts, else OSMesa, else a clear error when a context is asked for),
because MuJoCo and dm_control read ``MUJOCO_GL`` once, at import. It also
asks Mesa's software rasteriser for one thread per process
(``LP_NUM_THREADS=1`` unless set): frames of 120x90 are too small to gain
from threads, and environments run one per process. When standard error is
not a terminal (a log file, CI), progress bars redraw at most every 30 s
(``TQDM_MININTERVAL``, unless set), so a log gets a few lines per bar rather
than hundreds of carriage-return updates.
"""

import os
import sys

from leaps_mj.environment import gl_backend

gl_backend.configure()
os.environ.setdefault("LP_NUM_THREADS", "1")
if not (sys.stderr is not None and sys.stderr.isatty()):
    os.environ.setdefault("TQDM_MININTERVAL", "30")

__version__ = "0.1.0"


def load(*args, **kwargs):
    """Builds a RoomNav environment; see :func:`leaps_mj.environment.roomnav.load`."""
    from leaps_mj.environment import roomnav as env

    return env.load(*args, **kwargs)
