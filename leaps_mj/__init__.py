"""RoomNav-MJ and LEAPS: semantic multi-room navigation in MuJoCo.

Importing the package picks an off-screen OpenGL backend for MuJoCo when
``MUJOCO_GL`` is unset (EGL if Mesa's or a vendor's libEGL is present, else
OSMesa), because dm_control reads that variable once, at import. It also
asks Mesa's software rasteriser for one thread per process
(``LP_NUM_THREADS=1`` unless set): frames of 120x90 are too small to gain
from threads, and environments run one per process.
"""

import ctypes.util
import os


def _default_gl_backend() -> str:
    if ctypes.util.find_library("EGL"):
        return "egl"
    return "osmesa"


os.environ.setdefault("MUJOCO_GL", _default_gl_backend())
os.environ.setdefault("LP_NUM_THREADS", "1")
if os.environ["MUJOCO_GL"] == "osmesa":
    os.environ.setdefault("PYOPENGL_PLATFORM", "osmesa")
elif os.environ["MUJOCO_GL"] == "egl":
    os.environ.setdefault("PYOPENGL_PLATFORM", "egl")

__version__ = "0.1.0"


def load(*args, **kwargs):
    """Builds a RoomNav environment; see :func:`leaps_mj.environment.roomnav.load`."""
    from leaps_mj.environment import roomnav as env

    return env.load(*args, **kwargs)
