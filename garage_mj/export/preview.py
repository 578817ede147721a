"""``preview.png``: a top-down picture of a garage (opencv), north up.

Drawn from the same scene layout as the MJCF scene and the meshes, plus the road cells of the
road network: blocks (obstacles, walls), roads (darker asphalt with centre lines), stall outlines,
parked cars and pillars, entrance and exit, in the class colours of the meshes; a legend strip under
the garage names the entrance, the exit and the other colours.
"""

from __future__ import annotations

from collections.abc import Iterable
from pathlib import Path

import cv2
import numpy as np

from garage_mj.grid.garage import Garage
from garage_mj.scene.garage_scene import GarageScene, as_scene
from garage_mj.scene.layout import CLASS_RGBA, SceneLayout
from garage_mj.scene.semantics import Semantic
from garage_mj.scene.stalls import rectangle
from garage_mj.scene.world import DEFAULT_WORLD, WorldConfig

PIXELS_PER_METRE = 8.0  # [px/m] a 13x13 garage (117 m) is about 950 px wide
MARGIN = 1.0  # [m] around the outer walls
ROAD_RGB = (70, 72, 76)
BACKGROUND_RGB = (25, 25, 28)
CAR_LENGTH, CAR_WIDTH = 4.3, 1.9  # [m] models/parked_car footprint (inside a 4.5 m x 2.5 m stall)
LEGEND_ROW_PX = 22  # [px] height of one row of the legend strip under the garage
LEGEND_SWATCH_PX = 12  # [px] side of a legend's colour square
LEGEND_FONT_SCALE = 0.42  # of cv2's Hershey simplex font (about 9 px capitals)
_ORDER = (
    Semantic.FLOOR, Semantic.ENTRANCE, Semantic.EXIT, Semantic.ROAD_MARKING, Semantic.STALL_MARKING,
    Semantic.OBSTACLE, Semantic.WALL,
)


def _bgr(cls: Semantic) -> tuple[int, int, int]:
    r, g, b, _ = CLASS_RGBA[cls]
    return int(255 * b), int(255 * g), int(255 * r)


class _Canvas:
    def __init__(self, layout: SceneLayout, ppm: float) -> None:
        sx, sy = layout.size
        self.ppm, self.sy = ppm, sy
        self.img = np.zeros((int((sy + 2 * MARGIN) * ppm), int((sx + 2 * MARGIN) * ppm), 3), np.uint8)
        self.img[:] = BACKGROUND_RGB[::-1]

    def px(self, x: float, y: float) -> tuple[float, float]:
        return (x + MARGIN) * self.ppm, (self.sy - y + MARGIN) * self.ppm

    def rect(self, x0: float, y0: float, x1: float, y1: float, color) -> None:
        a, b = self.px(x0, y1), self.px(x1, y0)
        cv2.rectangle(self.img, (round(a[0]), round(a[1])), (round(b[0]) - 1, round(b[1]) - 1), color, -1)

    def poly(self, corners, color) -> None:
        pts = np.array([self.px(x, y) for x, y in corners]) * 16  # 4 bits of sub-pixel precision
        cv2.fillPoly(self.img, [pts.round().astype(np.int32)], color, cv2.LINE_AA, shift=4)


def legend_entries() -> list[tuple[str, tuple[int, int, int]]]:
    """The preview's legend: each label with its BGR colour, the entrance and the exit first."""
    return [("entrance", _bgr(Semantic.ENTRANCE)), ("exit", _bgr(Semantic.EXIT)), ("road", ROAD_RGB[::-1]),
            ("floor", _bgr(Semantic.FLOOR)), ("stall line", _bgr(Semantic.STALL_MARKING)),
            ("parked car", _bgr(Semantic.PARKED_CAR)), ("pillar", _bgr(Semantic.PILLAR)),
            ("obstacle", _bgr(Semantic.OBSTACLE)), ("wall", _bgr(Semantic.WALL))]


def _with_legend(img: np.ndarray) -> np.ndarray:
    """``img`` (BGR) with the legend strip under it: a colour square and a label per entry, in as many rows as
    the picture's width needs."""
    font, pad = cv2.FONT_HERSHEY_SIMPLEX, 8
    items = [(label, colour, cv2.getTextSize(label, font, LEGEND_FONT_SCALE, 1)[0][0] + LEGEND_SWATCH_PX + 2 * pad)
             for label, colour in legend_entries()]
    rows: list[list[tuple[str, tuple[int, int, int], int]]] = [[]]
    for item in items:
        if rows[-1] and pad + sum(w for *_, w in rows[-1]) + item[2] > img.shape[1]:
            rows.append([])
        rows[-1].append(item)
    strip = np.empty((LEGEND_ROW_PX * len(rows) + pad // 2, img.shape[1], 3), np.uint8)
    strip[:] = BACKGROUND_RGB[::-1]
    for k, row in enumerate(rows):
        x, mid = pad, k * LEGEND_ROW_PX + LEGEND_ROW_PX // 2
        for label, colour, width in row:
            top = mid - LEGEND_SWATCH_PX // 2
            cv2.rectangle(strip, (x, top), (x + LEGEND_SWATCH_PX - 1, top + LEGEND_SWATCH_PX - 1), colour, -1)
            cv2.rectangle(strip, (x, top), (x + LEGEND_SWATCH_PX - 1, top + LEGEND_SWATCH_PX - 1), (200, 200, 200), 1)
            cv2.putText(strip, label, (x + LEGEND_SWATCH_PX + 5, mid + 4), font, LEGEND_FONT_SCALE, (235, 235, 235), 1,
                        cv2.LINE_AA)
            x += width
    return np.concatenate([img, strip])


def render_preview(
    garage: Garage | GarageScene, *, world: WorldConfig = DEFAULT_WORLD, parked: Iterable[int] | None = None,
    pixels_per_metre: float = PIXELS_PER_METRE, legend: bool = True,
) -> np.ndarray:
    """The top-down picture as an (H, W, 3) RGB uint8 array, north up; ``legend``: with the legend strip under
    the garage (the garage keeps its pixels: the strip only adds rows at the bottom)."""
    scene = as_scene(garage, world)
    layout, world = scene.layout, scene.world
    canvas = _Canvas(layout, pixels_per_metre)
    boxes = sorted(layout.boxes, key=lambda b: _ORDER.index(b.cls) if b.cls in _ORDER else len(_ORDER))
    half_road, half = world.road_width / 2, world.block / 2
    for box in boxes:
        (cx, cy, _), (hx, hy, _) = box.center, box.half
        if box.yaw:  # a painted line of an angled stall
            canvas.poly(rectangle(cx, cy, box.yaw, 2 * hx, 2 * hy), _bgr(box.cls))
            continue
        canvas.rect(cx - hx, cy - hy, cx + hx, cy + hy, _bgr(box.cls))
        if box.cls == Semantic.FLOOR:  # asphalt of the roads, under the markings
            for cell in scene.network.cells.values():
                canvas.rect(cell.x - half_road, cell.y - half_road, cell.x + half_road, cell.y + half_road,
                            ROAD_RGB[::-1])
                for d in cell.openings:
                    ux, uy = {0: (-1, 0), 1: (1, 0), 2: (0, 1), 3: (0, -1)}[d]
                    x0, y0 = cell.x + ux * half_road, cell.y + uy * half_road
                    x1, y1 = cell.x + ux * half, cell.y + uy * half
                    canvas.rect(min(x0, x1) - half_road * abs(uy), min(y0, y1) - half_road * abs(ux),
                                max(x0, x1) + half_road * abs(uy), max(y0, y1) + half_road * abs(ux),
                                ROAD_RGB[::-1])
    occupied = None if parked is None else set(parked)
    for p in layout.parked_cars:
        if occupied is None or p.stall_id in occupied:
            canvas.poly(rectangle(p.x, p.y, p.yaw, CAR_LENGTH, CAR_WIDTH), _bgr(Semantic.PARKED_CAR))
    s = world.pillar_size / 2
    for p in layout.pillars:
        canvas.rect(p.x - s, p.y - s, p.x + s, p.y + s, _bgr(Semantic.PILLAR))
    img = _with_legend(canvas.img) if legend else canvas.img
    return img[..., ::-1].copy()


def write_preview(garage: Garage | GarageScene, path: str | Path, **kwargs) -> Path:
    """Write :func:`render_preview` as a PNG."""
    path = Path(path)
    if not cv2.imwrite(str(path), render_preview(garage, **kwargs)[..., ::-1]):
        raise OSError(f"could not write the preview image {path}")
    return path
