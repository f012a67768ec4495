"""One-pass off-screen rendering of segmentation and depth.

With the scene flags ``mjRND_SEGMENT`` and ``mjRND_IDCOLOR`` MuJoCo paints each
geom in a colour that encodes its index in the scene, and ``mjr_readPixels``
returns that colour buffer and the depth buffer from the same draw: both
observations for the price of one render (``mujoco.Renderer`` needs two).
The segment index is mapped to a geom id, then through a lookup table to a
segmentation class and to the geom's "see" mask.

The OpenGL backend is whatever ``MUJOCO_GL`` names (``leaps_mj`` picks EGL or
OSMesa when unset); a clear error lists what was tried when none works.
"""

from __future__ import annotations

import atexit
import os
import weakref

import mujoco
import numpy as np

from leaps_mj.environment import gl_backend
from leaps_mj.world import mjcf as house_mjcf

RenderError = gl_backend.RenderError

#: Objects holding GL resources that are still open (environments, renderers owning a context).
_OPEN: weakref.WeakSet = weakref.WeakSet()


def track(holder) -> None:
    """Closes ``holder`` (anything with ``close()``) at interpreter exit if it is still open then.

    Without this, an environment left open in a reference cycle is freed by
    the final garbage collection, after PyOpenGL has begun to unload, and
    ``GLContext.__del__`` prints an EGL traceback.
    """
    _OPEN.add(holder)


def _close_open() -> None:
    for holder in list(_OPEN):
        try:
            holder.close()
        except Exception:  # noqa: BLE001 - best effort at exit; nothing left to report to
            pass


def make_context(width: int, height: int) -> "mujoco.GLContext":
    """An off-screen GL context for the backend in ``MUJOCO_GL``.

    Raises:
      RenderError: naming the backend tried, the library missing and the package that provides it.
    """
    if gl_backend.problem() is not None:
        raise RenderError(gl_backend.problem())
    backend = os.environ.get("MUJOCO_GL", "")
    try:
        ctx = mujoco.GLContext(width, height)
        ctx.make_current()
        # After the backend's own exit hooks (MuJoCo's EGL backend terminates its display at exit,
        # registered with the first context): exit hooks run last-in first-out, so this one closes
        # what is open while the display still works.
        atexit.unregister(_close_open)
        atexit.register(_close_open)
    except Exception as e:  # noqa: BLE001 - backend errors come in many types
        raise RenderError(
            f"could not create an off-screen OpenGL context with MUJOCO_GL={backend!r} ({e}); "
            "tried that backend only: set MUJOCO_GL=egl (Mesa or NVIDIA libEGL; Debian: apt-get install "
            f"{gl_backend.LIBRARIES['egl'][1]}) or MUJOCO_GL=osmesa (Debian: apt-get install "
            f"{gl_backend.LIBRARIES['osmesa'][1]}) before importing leaps_mj"
        ) from e
    return ctx


class SegDepthRenderer:
    """Renders (segment geom id, depth) images from a named camera.

    Args:
      model: the compiled house model.
      width, height: image size in pixels.
      camera: name of the camera to render from.
      context: a GL context to share (one per process is enough); a new one
        is made, and owned, when None.
    """

    def __init__(self, model: mujoco.MjModel, width: int, height: int, camera: str = "agent/eye",
                 context: "mujoco.GLContext | None" = None):
        self.model = model
        self.width, self.height = width, height
        # No multisampling: it would blend segment colours at edges (and costs
        # a third of the frame in software); coarse curved primitives.
        model.vis.quality.offsamples = 0
        model.vis.quality.numslices = 10
        model.vis.quality.numstacks = 4
        # Nothing casts shadows: without this MuJoCo allocates a 4096² shadow
        # map per context (64 MB per cached house); the offscreen buffer
        # only needs this renderer's size.
        model.vis.quality.shadowsize = 0
        model.vis.global_.offwidth, model.vis.global_.offheight = width, height
        self._owns_ctx = context is None
        self._ctx = make_context(width, height) if context is None else context
        if self._owns_ctx:
            track(self)
        self._ctx.make_current()
        self._mjr = mujoco.MjrContext(model, mujoco.mjtFontScale.mjFONTSCALE_150)
        mujoco.mjr_setBuffer(mujoco.mjtFramebuffer.mjFB_OFFSCREEN, self._mjr)
        self._scene = mujoco.MjvScene(model, maxgeom=model.ngeom + 10)
        self._scene.flags[mujoco.mjtRndFlag.mjRND_SEGMENT] = True
        self._scene.flags[mujoco.mjtRndFlag.mjRND_IDCOLOR] = True
        self._opt = mujoco.MjvOption()
        self._opt.geomgroup[house_mjcf.AGENT_GROUP] = 0
        self._cam = mujoco.MjvCamera()
        self._cam.type = mujoco.mjtCamera.mjCAMERA_FIXED
        self._cam.fixedcamid = mujoco.mj_name2id(model, mujoco.mjtObj.mjOBJ_CAMERA, camera)
        if self._cam.fixedcamid < 0:
            raise ValueError(f"camera {camera!r} not in the model")
        self._pert = mujoco.MjvPerturb()
        self._rect = mujoco.MjrRect(0, 0, width, height)
        self._rgb = np.empty((height, width, 3), dtype=np.uint8)
        self._depth = np.empty((height, width), dtype=np.float32)
        extent = model.stat.extent
        self._near = model.vis.map.znear * extent
        self._far = model.vis.map.zfar * extent
        self._lut = None

    def _activate(self) -> None:
        """Makes the GL context current and binds this renderer's framebuffer.

        Renderers of several houses share one GL context; the bound offscreen
        framebuffer is context state, so each frame binds its own.
        """
        self._ctx.make_current()
        mujoco.mjr_setBuffer(mujoco.mjtFramebuffer.mjFB_OFFSCREEN, self._mjr)

    def render_segments(self, data: mujoco.MjData) -> tuple[np.ndarray, np.ndarray]:
        """Segment indices and depth in metres, both (H, W), top row first.

        A segment index is 0 where nothing was hit, else 1 + the geom's index
        in the scene; :attr:`segment_geoms` maps it to a model geom id. Indices
        fit in uint8 while the scene has fewer than 255 geoms (batched houses
        do), which keeps the per-pixel lookups of callers cheap.
        """
        self._activate()
        mujoco.mjv_updateScene(self.model, data, self._opt, self._pert, self._cam,
                               mujoco.mjtCatBit.mjCAT_ALL, self._scene)
        mujoco.mjr_render(self._rect, self._scene, self._mjr)
        mujoco.mjr_readPixels(self._rgb, self._depth, self._rect, self._mjr)
        if self._scene.ngeom < 255:
            seg = self._rgb[::-1, :, 0].copy()
        else:
            rgb = self._rgb[::-1].astype(np.int32)
            seg = rgb[..., 0] | (rgb[..., 1] << 8) | (rgb[..., 2] << 16)
        # OpenGL depth buffer (0..1, non-linear) → metres along the view axis.
        depth = self._near / (1.0 - self._depth[::-1] * (1.0 - self._near / self._far))
        return seg, depth

    def render(self, data: mujoco.MjData) -> tuple[np.ndarray, np.ndarray]:
        """Geom ids (-1 where nothing was hit) and depth in metres, both (H, W)."""
        seg, depth = self.render_segments(data)
        return self.segment_geoms[seg], depth

    @property
    def segment_geoms(self) -> np.ndarray:
        """Segment index → model geom id (-1 for nothing hit).

        The scene's geom list is the same every frame for a fixed model and
        fixed visual options, so it is read once, from a first scene update.
        """
        if self._lut is None:
            if self._scene.ngeom == 0:
                mujoco.mjv_updateScene(self.model, mujoco.MjData(self.model), self._opt, self._pert,
                                       self._cam, mujoco.mjtCatBit.mjCAT_ALL, self._scene)
            ngeom = self._scene.ngeom
            self._lut = np.array([-1] + [self._scene.geoms[i].objid for i in range(ngeom)], dtype=np.int32)
        return self._lut

    def render_rgb(self, data: mujoco.MjData) -> np.ndarray:
        """A colour image (H, W, 3) uint8 from the same camera (a second pass)."""
        self._activate()
        for flag in (mujoco.mjtRndFlag.mjRND_SEGMENT, mujoco.mjtRndFlag.mjRND_IDCOLOR):
            self._scene.flags[flag] = False
        try:
            mujoco.mjv_updateScene(self.model, data, self._opt, self._pert, self._cam,
                                   mujoco.mjtCatBit.mjCAT_ALL, self._scene)
            mujoco.mjr_render(self._rect, self._scene, self._mjr)
            mujoco.mjr_readPixels(self._rgb, None, self._rect, self._mjr)
        finally:
            for flag in (mujoco.mjtRndFlag.mjRND_SEGMENT, mujoco.mjtRndFlag.mjRND_IDCOLOR):
                self._scene.flags[flag] = True
        return self._rgb[::-1].copy()

    def close(self) -> None:
        """Frees the GL resources (safe to call twice)."""
        if self._mjr is not None:
            self._ctx.make_current()
            self._mjr.free()
            self._mjr = None
            if self._owns_ctx:
                self._ctx.free()


def subsample(frame, width: int, height: int) -> np.ndarray:
    """A (H, W) frame at ``width`` x ``height``, from a frame of that size or an integer multiple of it.

    The centre pixel of every k x k block is kept: the same rays as rendering
    at the smaller size, so the same frame (for policies trained at 40x30
    acting in the standard 120x90 environment).

    Raises:
      ValueError: for a frame of another size.
    """
    frame = np.asarray(frame)
    h, w = frame.shape[-2:]
    k = h // height
    if frame.ndim == 2 and k >= 1 and (h, w) == (k * height, k * width):
        return frame[k // 2::k, k // 2::k]
    raise ValueError(f"frame of shape {frame.shape}; this policy takes {width}x{height} frames "
                     f"(width x height) or an integer multiple of that size")
