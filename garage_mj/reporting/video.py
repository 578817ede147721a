"""MP4 video of one cruise test: the ``ego/top`` (or ``overview``) camera with the route drawn on.

Rendering RGB is the slow part of a test, so videos are small (320 x 240 at the control rate,
10 fps by default) and made one test at a time, never during a batch.
"""

from __future__ import annotations

import math
import os
import tempfile
from pathlib import Path
from typing import Any

import mujoco
import numpy as np

from garage_mj.core.fsutil import public_mode
from garage_mj.driving.sim.sensors import Camera, CameraConfig
from garage_mj.driving.sources import CruiseSettings, CruiseSource, cruise_seed

VIDEO_SIZE = (320, 240)  # [px] width, height
ROUTE_BGR = (40, 200, 255)  # orange-yellow route line
GOAL_BGR = (60, 220, 60)
TEXT_BGR = (255, 255, 255)
ROUTE_Z = 0.05  # [m] height of the drawn route above the floor


def project(model: mujoco.MjModel, data: mujoco.MjData, camera_id: int, points: np.ndarray,
            width: int, height: int) -> np.ndarray:
    """Pixel coordinates (N, 2) of world ``points`` (N, 3) in camera ``camera_id``; NaN behind it."""
    pos = data.cam_xpos[camera_id]
    rot = data.cam_xmat[camera_id].reshape(3, 3)  # columns: camera x (right), y (up), z (backwards)
    d = (np.asarray(points, dtype=float) - pos) @ rot
    fovy = float(model.cam_fovy[camera_id])
    if int(model.cam_projection[camera_id]) == int(mujoco.mjtProjection.mjPROJ_ORTHOGRAPHIC):
        scale = height / fovy  # fovy is the view height in metres
        u, v = d[:, 0] * scale, d[:, 1] * scale
    else:
        f = (height / 2) / math.tan(math.radians(fovy) / 2)
        depth = -d[:, 2]
        with np.errstate(divide="ignore", invalid="ignore"):
            u, v = f * d[:, 0] / depth, f * d[:, 1] / depth
        u[depth <= 1e-6] = np.nan
    return np.stack([width / 2 + u, height / 2 - v], axis=1)


def _draw(frame: np.ndarray, pixels: np.ndarray, lines: list[str]) -> np.ndarray:
    import cv2

    img = np.ascontiguousarray(frame[..., ::-1])  # RGB -> BGR
    ok = np.isfinite(pixels).all(axis=1)
    pts = np.round(pixels[ok]).astype(np.int32)
    if len(pts) >= 2:
        cv2.polylines(img, [pts.reshape(-1, 1, 2)], False, ROUTE_BGR, 2, cv2.LINE_AA)
    if ok[-1]:
        cv2.circle(img, tuple(int(v) for v in np.round(pixels[-1])), 5, GOAL_BGR, -1, cv2.LINE_AA)
    for i, text in enumerate(lines):
        cv2.putText(img, text, (6, 16 + 16 * i), cv2.FONT_HERSHEY_SIMPLEX, 0.45, TEXT_BGR, 1, cv2.LINE_AA)
    return img


def record_video(
    source: Any,
    path: str | Path,
    settings: CruiseSettings | None = None,
    test: int = 0,
    camera: str = "ego/top",
    size: tuple[int, int] = VIDEO_SIZE,
) -> Path:
    """Drive test ``test`` of a :class:`~garage_mj.driving.sources.CruiseSource` (same seed as the batch) into an MP4.

    ``settings``: those of the run the test was in (default :class:`CruiseSettings`); an action type of
    None is the driver's own, a given one is used as it is (the run warned about it already).
    """
    import cv2

    from garage_mj.driving.drivers import choose_action_type, load_driver
    from garage_mj.driving.sim.drive_env import GarageDriveEnv

    settings = settings if settings is not None else CruiseSettings()
    src = source if isinstance(source, CruiseSource) else CruiseSource.from_garage(source)
    choice = choose_action_type(settings.driver, settings.action_type, warn=False)
    drv = load_driver(settings.driver, **(settings.driver_kwargs or {}))
    env = GarageDriveEnv(garage=src.garage, action_type=choice.action_type, occupancy=settings.occupancy,
                         infeasible="report", **settings.task_kwargs(),
                         **(settings.env or {}))  # as the cruise runner: same seed, same test
    width, height = size
    cam = Camera(env.model, CameraConfig(camera=camera, width=width, height=height, rgb=True, depth=False,
                                         segmentation=False))
    out = Path(path)
    out.parent.mkdir(parents=True, exist_ok=True)
    fd, name = tempfile.mkstemp(prefix=f".{out.stem}.", suffix=".tmp.mp4", dir=out.parent)  # O_EXCL, unpredictable
    os.close(fd)
    tmp = Path(name)
    writer = cv2.VideoWriter(str(tmp), cv2.VideoWriter_fourcc(*"mp4v"), float(round(1 / env.dt)), (width, height))
    if not writer.isOpened():
        tmp.unlink(missing_ok=True)
        env.close()
        cam.close()
        raise RuntimeError(f"opencv cannot write MP4 to {tmp}; install opencv-python-headless with FFmpeg")
    try:
        test_seed = cruise_seed(settings.seed, src.hash, test)
        obs, info = env.reset(seed=test_seed)
        drv.reset(env.driver_info(test_seed))
        route3 = np.column_stack([env.route.points, np.full(len(env.route.points), ROUTE_Z)])
        status = f"{src.name} test {test} -> stall {info['target_stall']}"
        while True:
            pixels = project(env.model, env.data, cam.camera_id, route3, width, height)
            lines = [status, f"t {info['time']:5.1f} s  v {float(obs['speed'][0]):4.1f} m/s"]
            if "outcome" in info:
                lines.append(f"{info['outcome']}" + (f": hit {info['hit']}" if info.get("hit") else ""))
            writer.write(_draw(cam.render(env.data)["rgb"], pixels, lines))
            if "outcome" in info:
                break
            obs, _, _, _, info = env.step(drv.act(obs))
    except BaseException:
        tmp.unlink(missing_ok=True)
        raise
    finally:
        writer.release()
        cam.close()
        env.close()
    os.chmod(tmp, public_mode())
    tmp.replace(out)
    return out
