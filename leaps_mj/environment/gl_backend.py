"""Which off-screen OpenGL backend MuJoCo uses: EGL, else OSMesa, else a clear error.

MuJoCo and dm_control read ``MUJOCO_GL`` once, when they are first imported,
and a backend whose library is missing fails deep inside PyOpenGL (for
OSMesa: ``'NoneType' object has no attribute 'glGetError'``, at
``import mujoco``). :func:`configure` runs when :mod:`leaps_mj` is imported,
before any of that, and settles the variable:

* ``MUJOCO_GL`` unset: EGL when a device display initialises (probed through
  libEGL with ctypes, a few milliseconds), else OSMesa when libOSMesa is
  installed;
* ``MUJOCO_GL`` set to ``egl`` or ``osmesa`` whose library is missing, or
  unset with neither usable: the variable becomes ``disabled``, so that
  everything that does not draw (house generation, statistics, planning)
  still imports, and the first GL context asked for raises
  :class:`RenderError` saying which backend was tried, which library is
  missing and the Debian package that provides it.

The choice is written to ``os.environ``, so worker processes inherit it and
do not probe again. ``PYOPENGL_PLATFORM`` follows the backend.
"""

from __future__ import annotations

import ctypes
import ctypes.util
import os

#: backend -> (library name for ctypes.util.find_library, Debian package).
LIBRARIES = {"egl": ("EGL", "libegl1 (with libegl-mesa0 for software rendering)"),
             "osmesa": ("OSMesa", "libosmesa6")}
#: Values of MUJOCO_GL meaning "no rendering", for MuJoCo and dm_control alike.
DISABLED = "disabled"
_EGL_PLATFORM_DEVICE_EXT = 0x313F

#: Where :func:`configure` leaves why rendering is unavailable (inherited by worker processes).
PROBLEM_VARIABLE = "LEAPS_MJ_GL_PROBLEM"


class RenderError(RuntimeError):
    """No off-screen OpenGL context can be created."""


def _library(backend: str) -> str | None:
    return ctypes.util.find_library(LIBRARIES[backend][0])


def egl_starts() -> bool:
    """Whether libEGL initialises a display on some EGL device (what MuJoCo's EGL backend needs)."""
    path = _library("egl")
    if path is None:
        return False
    try:
        egl = ctypes.CDLL(path)
        vp = ctypes.c_void_p
        egl.eglGetProcAddress.restype = vp
        egl.eglGetProcAddress.argtypes = [ctypes.c_char_p]
        egl.eglInitialize.argtypes = [vp, vp, vp]
        egl.eglTerminate.argtypes = [vp]
        query_ptr = egl.eglGetProcAddress(b"eglQueryDevicesEXT")
        display_ptr = egl.eglGetProcAddress(b"eglGetPlatformDisplayEXT")
        if not (query_ptr and display_ptr):
            return False
        query = ctypes.CFUNCTYPE(ctypes.c_uint, ctypes.c_int, ctypes.POINTER(vp), ctypes.POINTER(ctypes.c_int))(
            query_ptr)
        get_display = ctypes.CFUNCTYPE(vp, ctypes.c_uint, vp, vp)(display_ptr)
        devices, count = (vp * 16)(), ctypes.c_int()
        if not query(16, devices, ctypes.byref(count)):
            return False
        for i in range(count.value):
            display = get_display(_EGL_PLATFORM_DEVICE_EXT, devices[i], None)
            if display and egl.eglInitialize(display, None, None):
                egl.eglTerminate(display)
                return True
    except (OSError, AttributeError):
        return False
    return False


def _missing(backend: str) -> str:
    name, package = LIBRARIES[backend]
    return f"MUJOCO_GL={backend!r} needs lib{name}, which is not installed (Debian: apt-get install {package})"


def problem() -> str | None:
    """Why no GL context can be made in this process, or None when a backend was configured."""
    return os.environ.get(PROBLEM_VARIABLE) or None


def configure() -> str:
    """Settles ``MUJOCO_GL`` (and ``PYOPENGL_PLATFORM``) before MuJoCo is imported; returns the backend."""
    problem = None
    chosen = os.environ.get("MUJOCO_GL", "").strip().lower()
    if not chosen:
        if egl_starts():
            chosen = "egl"
        elif _library("osmesa") is not None:
            chosen = "osmesa"
        else:
            problem = ("no off-screen OpenGL backend: EGL does not start (no libEGL, or no EGL device "
                       f"initialises; Debian: apt-get install {LIBRARIES['egl'][1]}) and libOSMesa is not "
                       f"installed (Debian: apt-get install {LIBRARIES['osmesa'][1]})")
            chosen = DISABLED
    elif chosen in LIBRARIES and _library(chosen) is None:
        problem = _missing(chosen)
        chosen = DISABLED
    os.environ["MUJOCO_GL"] = chosen
    if problem is not None:
        os.environ[PROBLEM_VARIABLE] = problem
    if chosen in LIBRARIES:
        os.environ.setdefault("PYOPENGL_PLATFORM", chosen)
    return chosen
