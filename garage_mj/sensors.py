"""Offscreen camera sensor: RGB, depth in metres and SPEC section 6 segmentation via ``mujoco.Renderer``.

Rendering is headless. ``MUJOCO_GL`` defaults to ``egl`` (set here if this module is the first to
import MuJoCo; ``garage_mj`` sets it too); when EGL cannot start, OSMesa is tried, and when
neither works one :class:`RenderError` line names the fix.
"""

from __future__ import annotations

import os

os.environ.setdefault("MUJOCO_GL", "egl")

from dataclasses import dataclass  # noqa: E402

import mujoco  # noqa: E402
import numpy as np  # noqa: E402

from garage_mj.semantics import geom_classes  # noqa: E402

GL_FIX = (
    "MUJOCO_GL=egl needs libEGL/Mesa (apt-get install libegl1 libgl1-mesa-dri), "
    "or use MUJOCO_GL=osmesa (apt-get install libosmesa6)"
)


class RenderError(RuntimeError):
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


def _use_backend(name: str) -> None:
    """Point ``mujoco.Renderer`` at GL backend ``name`` (it reads the module-level GLContext)."""
    from mujoco.rendering.classic import gl_context

    if name == "egl":
        from mujoco.egl import GLContext
    elif name == "osmesa":
        from mujoco.osmesa import GLContext
    else:
        return  # glfw and friends: what MuJoCo chose at import
    gl_context.GLContext = GLContext


def open_renderer(model: mujoco.MjModel, height: int, width: int) -> mujoco.Renderer:
    """A ``mujoco.Renderer``, trying EGL then OSMesa; :class:`RenderError` naming the fix if none works."""
    from mujoco.rendering.classic import gl_context

    original = getattr(gl_context, "GLContext", None)
    errors = []
    for name in _backends():
        try:
            _use_backend(name)
            return mujoco.Renderer(model, height=height, width=width)
        except ValueError:
            raise  # image larger than the offscreen buffer: a model problem, not GL
        except Exception as exc:  # noqa: BLE001 - each backend fails in its own way
            errors.append(f"{name}: {str(exc).splitlines()[0] if str(exc) else type(exc).__name__}")
    gl_context.GLContext = original
    raise RenderError(f"offscreen rendering unavailable ({'; '.join(errors)}); {GL_FIX}")


class Camera:
    """Renders one MJCF camera of a compiled model: ``render(data) -> {"rgb"?, "depth", "segmentation"}``.

    Depth is float32 metres along the optical axis, clipped to ``far``; segmentation is uint8
    :class:`garage_mj.semantics.Semantic` ids. Sets the model's clipping planes to ``near``/``far``.
    """

    def __init__(self, model: mujoco.MjModel, config: CameraConfig | None = None):
        self.config = cfg = config or CameraConfig()
        self.model = model
        self.camera_id = mujoco.mj_name2id(model, mujoco.mjtObj.mjOBJ_CAMERA, cfg.camera)
        if self.camera_id < 0:
            names = [mujoco.mj_id2name(model, mujoco.mjtObj.mjOBJ_CAMERA, i) for i in range(model.ncam)]
            raise ValueError(f"the model has no camera {cfg.camera!r}; cameras: {', '.join(map(str, names))}")
        extent = float(model.stat.extent)
        model.vis.map.znear = cfg.near / extent
        model.vis.map.zfar = cfg.far / extent
        if model.vis.global_.offwidth < cfg.width or model.vis.global_.offheight < cfg.height:
            model.vis.global_.offwidth = max(model.vis.global_.offwidth, cfg.width)
            model.vis.global_.offheight = max(model.vis.global_.offheight, cfg.height)
        self._renderer = open_renderer(model, cfg.height, cfg.width)
        flags = self._renderer.scene.flags
        flags[mujoco.mjtRndFlag.mjRND_SHADOW] = cfg.shadows
        flags[mujoco.mjtRndFlag.mjRND_REFLECTION] = cfg.shadows
        # class per geom id, plus one slot (index ngeom) for background and non-geom objects
        self._lut = np.append(geom_classes(model), 0).astype(np.uint8)

    def _update(self, data: mujoco.MjData) -> None:
        self._renderer.update_scene(data, camera=self.camera_id)

    def _depth(self) -> np.ndarray:
        r = self._renderer
        r.enable_depth_rendering()
        try:
            depth = r.render()
        finally:
            r.disable_depth_rendering()
        return np.minimum(depth, np.float32(self.config.far), out=depth)

    def _segmentation(self) -> np.ndarray:
        r = self._renderer
        r.enable_segmentation_rendering()
        try:
            raw = r.render()
        finally:
            r.disable_segmentation_rendering()
        objid, objtype = raw[..., 0], raw[..., 1]
        idx = np.where(objtype == int(mujoco.mjtObj.mjOBJ_GEOM), objid, self.model.ngeom)
        return self._lut[idx]

    def render(self, data: mujoco.MjData) -> dict[str, np.ndarray]:
        """The images the config asks for, from the current state of ``data``."""
        self._update(data)
        out: dict[str, np.ndarray] = {}
        if self.config.rgb:
            out["rgb"] = self._renderer.render()
        if self.config.depth:
            out["depth"] = self._depth()
        if self.config.segmentation:
            out["segmentation"] = self._segmentation()
        return out

    def rgb(self, data: mujoco.MjData) -> np.ndarray:
        """(H, W, 3) uint8 colour image."""
        self._update(data)
        return self._renderer.render()

    def depth(self, data: mujoco.MjData) -> np.ndarray:
        """(H, W) float32 depth [m]."""
        self._update(data)
        return self._depth()

    def segmentation(self, data: mujoco.MjData) -> np.ndarray:
        """(H, W) uint8 semantic class ids."""
        self._update(data)
        return self._segmentation()

    def close(self) -> None:
        """Free the GL context (also done when garbage-collected)."""
        if self._renderer is not None:
            self._renderer.close()
            self._renderer = None

    def __enter__(self) -> Camera:
        return self

    def __exit__(self, *exc) -> None:
        self.close()
