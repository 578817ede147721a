"""Offscreen camera sensor: RGB, depth in metres and docs/spec.md section 6 segmentation.

Rendering is headless. ``MUJOCO_GL`` defaults to ``egl`` (set here if this module is the first to
import MuJoCo; ``garage_mj`` sets it too); when EGL cannot start, OSMesa is tried, and when
neither works one :class:`RenderError` line names the fix.

``LP_NUM_THREADS`` defaults to 0 (set here, before any GL context, unless already set): under
software GL (Mesa llvmpipe, no GPU) the frame is then drawn in the calling thread. A 64x64 frame
is a single tile, so llvmpipe's rasterizer threads gain nothing, and handing each frame to them
costs a sleep and a wake-up: between two frames the drive env steps the physics for a millisecond
and the threads fall asleep. On the 2-core machine with other jobs running that cost 0.25-1 ms a
frame (2 threads, the default, or 1), against a steady 0.25-0.3 ms in the calling thread; with one
cruise worker per core it also keeps workers from competing with each other's threads.
A GPU ignores the variable; set it yourself for large software renders on many cores.

Speed (software GL renders most frames of a cruise test): the camera drives MuJoCo's renderer
directly instead of ``mujoco.Renderer``, with one ``mjv_updateScene`` and ONE segmentation pass per
frame, reading the ID colours and the depth buffer of the same frame (``mujoco.Renderer`` renders
twice and maps ids in Python). Geoms whose bounding sphere lies outside the view frustum (or
beyond ``far``) are left out of the scene before it is built, so a frame costs what the camera
sees, not the size of the garage. Markings stay in: segmentation shows road and stall markings.
Depth/segmentation-only cameras leave out sites (the entrance and exit markers, spheres nothing
collides with, which segmentation labelled "nothing"): they are no part of the world a sensor sees;
colour cameras, for people, keep them.
RGB, when asked for, is one more ordinary pass. Depth/segmentation-only cameras also render into a
framebuffer of exactly the image size with no multisampling and one quad per box face.

Profile (m5_13x13_aligned, 64x64, Mesa llvmpipe, 2 cores): mujoco.Renderer spent ~4.3 ms a frame
in two ``mjr_render`` passes plus Python (float64 depth, a per-geom Python loop for ids);
``mjv_updateScene`` and ``mjr_readPixels`` cost <0.1 ms. ``mjr_render`` is ~10-35 us per drawn
geom (box faces of 4x4 quads, 4x MSAA on a 1280x960 buffer) and ~0 for an empty scene, so the
wins are one pass, fewer drawn geoms (culling) and cheaper geoms: ~0.6-1 ms a frame.
"""

from __future__ import annotations

import os

os.environ.setdefault("MUJOCO_GL", "egl")
os.environ.setdefault("LP_NUM_THREADS", "0")  # read by Mesa when the first GL context starts

from dataclasses import dataclass  # noqa: E402

import mujoco  # noqa: E402
import numpy as np  # noqa: E402

from garage_mj.core.errors import GarageMJError  # noqa: E402
from garage_mj.scene.semantics import geom_classes  # noqa: E402

GL_FIX = (
    "MUJOCO_GL=egl needs libEGL/Mesa (apt-get install libegl1 libgl1-mesa-dri), "
    "or use MUJOCO_GL=osmesa (apt-get install libosmesa6)"
)


class RenderError(GarageMJError, RuntimeError):
    """Offscreen rendering is unavailable (no usable OpenGL); the message names the fix."""


@dataclass(frozen=True)
class CameraConfig:
    """The forward camera (defaults: the paper's front camera, small for speed)."""

    camera: str = "ego/front"  # MJCF camera name
    width: int = 64  # [px]
    height: int = 64  # [px]
    rate_hz: float = 10.0  # [Hz] frames per simulated second (the control rate of a drive env)
    rgb: bool = False  # render colour too (slower; depth + segmentation suffice for drivers)
    depth: bool = True
    segmentation: bool = True
    near: float = 0.05  # [m] near clipping plane
    far: float = 50.0  # [m] far clipping plane; depth reads at most this
    shadows: bool = False  # RGB shadows cost ~10x the frame time under software GL

    def __post_init__(self) -> None:
        if self.width <= 0 or self.height <= 0:
            raise ValueError(f"camera image size must be positive, got {self.width}x{self.height}")
        if self.rate_hz <= 0:
            raise ValueError(f"camera rate_hz must be positive, got {self.rate_hz}")
        if not 0 < self.near < self.far:
            raise ValueError(f"camera needs 0 < near < far, got near={self.near} far={self.far}")

    @property
    def period(self) -> float:
        """Seconds between frames."""
        return 1.0 / self.rate_hz


def _backends() -> list[str]:
    """GL backends to try, in order: the one asked for, then OSMesa when EGL was asked for."""
    asked = os.environ.get("MUJOCO_GL", "egl").lower().strip() or "glfw"
    return [asked, "osmesa"] if asked == "egl" else [asked]


def _gl_context_class(name: str):
    """The ``GLContext`` class of backend ``name`` (MuJoCo's default for glfw and friends)."""
    if name == "egl":
        from mujoco.egl import GLContext
    elif name == "osmesa":
        from mujoco.osmesa import GLContext
    else:
        from mujoco.rendering.classic.gl_context import GLContext
    return GLContext


def open_context(model: mujoco.MjModel, height: int, width: int, lean: bool = False):
    """``(gl_context, mjr_context)`` for offscreen rendering, trying EGL then OSMesa.

    The offscreen framebuffer is exactly ``width`` x ``height``. ``lean`` (images nobody looks at:
    depth, segmentation) also drops multisampling and subdivides box faces into one quad, not
    ``vis.quality.numquads``^2; under software GL these make a frame ~3x faster (profile in the
    module docstring). The model is left as it was: a later ``mujoco.Renderer`` sees its own settings.
    Raises :class:`RenderError` naming the fix when no backend works.
    """
    vis = model.vis
    saved = (vis.global_.offwidth, vis.global_.offheight, vis.quality.offsamples, vis.quality.numquads)
    vis.global_.offwidth, vis.global_.offheight = width, height
    if lean:
        vis.quality.offsamples, vis.quality.numquads = 0, 1
    try:
        return _open_context(model, height, width)
    finally:
        vis.global_.offwidth, vis.global_.offheight, vis.quality.offsamples, vis.quality.numquads = saved


def _open_context(model: mujoco.MjModel, height: int, width: int):
    errors = []
    for name in _backends():
        gl = None
        try:
            gl = _gl_context_class(name)(width, height)
            gl.make_current()
            ctx = mujoco.MjrContext(model, mujoco.mjtFontScale.mjFONTSCALE_150)
            mujoco.mjr_setBuffer(mujoco.mjtFramebuffer.mjFB_OFFSCREEN, ctx)
            ctx.readDepthMap = mujoco.mjtDepthMap.mjDEPTH_ZEROFAR
            return gl, ctx
        except Exception as exc:  # noqa: BLE001 - each backend fails in its own way
            errors.append(f"{name}: {str(exc).splitlines()[0] if str(exc) else type(exc).__name__}")
            if gl is not None:
                try:
                    gl.free()
                except Exception:  # noqa: BLE001 - a half-made context may not free cleanly
                    pass
    raise RenderError(f"offscreen rendering unavailable ({'; '.join(errors)}); {GL_FIX}")


CULL_MARGIN = np.deg2rad(2.0)  # [rad] widens the culling frustum: never cull a geom at the image edge
_GEOM = int(mujoco.mjtObj.mjOBJ_GEOM)
_HIDDEN_GROUP = 5  # geom group the culled geoms visit while the scene is built (hidden in the option)


class Camera:
    """Renders one MJCF camera of a compiled model: ``render(data) -> {"rgb"?, "depth", "segmentation"}``.

    Depth is float32 metres along the optical axis, clipped to ``far``; segmentation is uint8
    :class:`garage_mj.scene.semantics.Semantic` ids. Sets the model's clipping planes to ``near``/``far``.
    """

    def __init__(self, model: mujoco.MjModel, config: CameraConfig | None = None, cull: bool = True,
                 share: Camera | None = None):
        self.config = cfg = config or CameraConfig()
        self.model = model
        self.camera_id = mujoco.mj_name2id(model, mujoco.mjtObj.mjOBJ_CAMERA, cfg.camera)
        if self.camera_id < 0:
            names = [mujoco.mj_id2name(model, mujoco.mjtObj.mjOBJ_CAMERA, i) for i in range(model.ncam)]
            raise ValueError(f"the model has no camera {cfg.camera!r}; cameras: {', '.join(map(str, names))}")
        extent = float(model.stat.extent)
        model.vis.map.znear = cfg.near / extent
        model.vis.map.zfar = cfg.far / extent
        # ``share``: another camera of the same model rendering images of the same size and kind (a car's rear
        # camera beside its front one) lends its GL context; one context saves its memory and a context switch
        # per frame. The lender frees it; it must outlive this camera.
        self._owner = share is None or share.model is not model or share._ctx is None or (
            (share.config.width, share.config.height, share.config.rgb) != (cfg.width, cfg.height, cfg.rgb))
        if self._owner:
            self._gl, self._ctx = open_context(model, cfg.height, cfg.width, lean=not cfg.rgb)
        else:
            self._gl, self._ctx = share._gl, share._ctx
        self._rect = mujoco.MjrRect(0, 0, cfg.width, cfg.height)
        self._scene = mujoco.MjvScene(model, maxgeom=model.ngeom + model.nsite + 100)
        self._option = mujoco.MjvOption()
        self._option.geomgroup[_HIDDEN_GROUP] = 0
        self._option.flags[mujoco.mjtVisFlag.mjVIS_RANGEFINDER] = 0  # a rangefinder's ray is no part of the world
        if not cfg.rgb:  # a sensor's images: the marker spheres are no part of the world it sees
            self._option.sitegroup[:] = 0
        self._perturb = mujoco.MjvPerturb()
        self._cam = mujoco.MjvCamera()
        self._cam.type = mujoco.mjtCamera.mjCAMERA_FIXED
        self._cam.fixedcamid = self.camera_id
        flags = self._scene.flags
        flags[mujoco.mjtRndFlag.mjRND_SHADOW] = cfg.shadows
        flags[mujoco.mjtRndFlag.mjRND_REFLECTION] = cfg.shadows
        self._rgb_buf = np.empty((cfg.height, cfg.width, 3), np.uint8)
        self._depth_buf = np.empty((cfg.height, cfg.width), np.float32)
        self._metres = np.empty((cfg.height, cfg.width), np.float64)  # depth in metres, computed in place
        # the depth buffer's constants (float32 as mujoco.Renderer computes them), worked out once
        near, far = np.float32(cfg.near), np.float32(cfg.far)
        self._far, self._span = far, far - near
        self._c = np.float32(-0.5) * (-(far + near) / (far - near)) - np.float32(0.5)
        self._d = np.float32(-0.5) * (-(np.float32(2) * far * near) / (far - near))
        # class per geom id, plus one slot (index ngeom) for background and non-geom objects
        self._lut = np.append(geom_classes(model), 0).astype(np.uint8)
        perspective = model.cam_projection[self.camera_id] == mujoco.mjtProjection.mjPROJ_PERSPECTIVE
        # a camera with a physical sensor size gets its frustum from intrinsics, not fovy: no culling
        self._cull = cull and perspective and not model.cam_sensorsize[self.camera_id].any()
        if self._cull:
            half_y = np.deg2rad(float(model.cam_fovy[self.camera_id])) / 2
            half_x = np.arctan(np.tan(half_y) * cfg.width / cfg.height)
            a, b = half_x + CULL_MARGIN, half_y + CULL_MARGIN
            # outward normals (columns) of the frustum's planes in camera coordinates (x right, y up,
            # -z ahead): four sides, then near and far
            self._planes = np.array([[np.cos(a), 0, np.sin(a)], [-np.cos(a), 0, np.sin(a)],
                                     [0, np.cos(b), np.sin(b)], [0, -np.cos(b), np.sin(b)],
                                     [0, 0, 1], [0, 0, -1]]).T
            # a geom is out when its centre lies farther than its bounding radius beyond a plane
            # (the near and far planes sit near and far ahead); planes (rbound 0) are always drawn
            r = np.where(model.geom_rbound > 0, model.geom_rbound, np.inf)
            self._bounds = np.stack([r, r, r, r, r - cfg.near, r + cfg.far], axis=1)

    def _culled(self, data: mujoco.MjData) -> np.ndarray:
        """Bool per geom: its bounding sphere lies wholly outside the view frustum."""
        cid = self.camera_id
        planes = data.cam_xmat[cid].reshape(3, 3) @ self._planes  # the planes' normals in world coordinates
        return ((data.geom_xpos - data.cam_xpos[cid]) @ planes > self._bounds).any(axis=1)

    def _update(self, data: mujoco.MjData) -> None:
        m = self.model
        if not self._cull:
            mujoco.mjv_updateScene(m, data, self._option, self._perturb, self._cam,
                                   mujoco.mjtCatBit.mjCAT_ALL, self._scene)
            return
        culled = self._culled(data)
        groups = m.geom_group.copy()
        m.geom_group[culled] = _HIDDEN_GROUP
        try:
            mujoco.mjv_updateScene(m, data, self._option, self._perturb, self._cam,
                                   mujoco.mjtCatBit.mjCAT_ALL, self._scene)
        finally:
            m.geom_group[:] = groups

    def _draw(self, segment: bool) -> None:
        flags = self._scene.flags
        flags[mujoco.mjtRndFlag.mjRND_SEGMENT] = segment
        flags[mujoco.mjtRndFlag.mjRND_IDCOLOR] = segment
        if self._ctx is None:
            raise RuntimeError("render cannot be called after close")
        self._gl.make_current()
        mujoco.mjr_render(self._rect, self._scene, self._ctx)

    def _rgb(self) -> np.ndarray:
        self._draw(segment=False)
        mujoco.mjr_readPixels(self._rgb_buf, None, self._rect, self._ctx)
        return self._rgb_buf[::-1].copy()

    def _depth_and_segmentation(self) -> tuple[np.ndarray, np.ndarray]:
        """One segmentation pass: its ID colours and its depth buffer, read together."""
        self._draw(segment=True)
        mujoco.mjr_readPixels(self._rgb_buf, self._depth_buf, self._rect, self._ctx)
        # depth: undo the reversed-Z perspective projection (as mujoco.Renderer does), in float64
        z = self._metres
        np.copyto(z, self._depth_buf[::-1])
        if self._scene.camera[0].orthographic:
            z *= self._span
            np.subtract(self._far, z, out=z)
        else:
            z += self._c
            np.divide(self._d, z, out=z)
        depth = np.minimum(z, self._far, out=z).astype(np.float32)
        # segmentation: colour = scene geom index + 1 (0 = nothing); scene geom -> model geom -> class
        scn = self._scene
        n = scn.ngeom
        if n < 255:  # every index + 1 fits the red byte; green and blue are 0
            segid = self._rgb_buf[::-1, :, 0]
        else:
            rgb = self._rgb_buf[::-1].astype(np.int32)
            segid = rgb[..., 0] | (rgb[..., 1] << 8) | (rgb[..., 2] << 16)
        table = np.zeros(n + 2, np.uint8)  # [0] nothing, [1..n] scene geoms, [n+1] out of range
        geom, none = _GEOM, self.model.ngeom
        table[1:n + 1] = self._lut[[g.objid if g.objtype == geom else none for g in scn.geoms[:n]]]
        return depth, np.take(table, segid, mode="clip")  # an id past n reads as out of range

    def render(self, data: mujoco.MjData) -> dict[str, np.ndarray]:
        """The images the config asks for, from the current state of ``data``."""
        self._update(data)
        out: dict[str, np.ndarray] = {}
        if self.config.rgb:
            out["rgb"] = self._rgb()
        if self.config.depth or self.config.segmentation:
            depth, seg = self._depth_and_segmentation()
            if self.config.depth:
                out["depth"] = depth
            if self.config.segmentation:
                out["segmentation"] = seg
        return out

    def rgb(self, data: mujoco.MjData) -> np.ndarray:
        """(H, W, 3) uint8 colour image."""
        self._update(data)
        return self._rgb()

    def depth(self, data: mujoco.MjData) -> np.ndarray:
        """(H, W) float32 depth [m]."""
        self._update(data)
        return self._depth_and_segmentation()[0]

    def segmentation(self, data: mujoco.MjData) -> np.ndarray:
        """(H, W) uint8 semantic class ids."""
        self._update(data)
        return self._depth_and_segmentation()[1]

    def close(self) -> None:
        """Free the GL context (also done when garbage-collected); a borrowed one is its lender's to free."""
        if not self._owner:
            self._ctx = self._gl = None
            return
        if self._ctx is not None:
            self._gl.make_current()
            self._ctx.free()
            self._ctx = None
        if self._gl is not None:
            self._gl.free()
            self._gl = None

    def __del__(self) -> None:
        try:
            self.close()
        except Exception:  # noqa: BLE001 - interpreter shutdown may have torn GL down already
            pass

    def __enter__(self) -> Camera:
        return self

    def __exit__(self, *exc) -> None:
        self.close()
