"""Figures of the generation stage (matplotlib, Agg backend, PNG files).

- :func:`convergence`: return vs episode, mean over the seeds of a map with a 95% confidence
  band (paper Fig. "Convergence curves"), one panel per map, read from the runs' monitor logs.
- :func:`heatmap`: difficulty (x) vs coverage (y) in 0.1 bins, count per cell (paper Fig. "Heatmap");
  the paper's difficulty, or the route difficulty (``metric="route"``).
- :func:`driver_curve`: a learned driver's training curve (``garage-mj train-driver``'s ``curve.csv``):
  validation success and agreement with the oracle per DAgger iteration, over the states seen.
- :func:`garage_png`: a top-down picture of one garage, a colour per block code, a legend and the
  road graph (tiles and segments) drawn over it.
"""

from __future__ import annotations

import io
import json
from collections.abc import Sequence
from pathlib import Path

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402
from matplotlib.colors import ListedColormap  # noqa: E402
from matplotlib.patches import Patch  # noqa: E402

from garage_mj.core.errors import GarageMJError  # noqa: E402
from garage_mj.core.fsutil import atomic_write  # noqa: E402
from garage_mj.core.geometry import DELTAS  # noqa: E402
from garage_mj.grid.blocks import NUM_CODES, Block  # noqa: E402
from garage_mj.grid.garage import Garage  # noqa: E402
from garage_mj.grid.image import BLOCK_COLOURS as _BLOCK_COLOURS
from garage_mj.grid.road_segments import Tile, analyse  # noqa: E402

BIN = 0.1  # heatmap cell width in difficulty and coverage
CONFIDENCE = 0.95
DPI = 120
MAX_PANEL_COLUMNS = 3  # convergence panels per row

#: Colour of each block code in :func:`garage_png` (the table of :mod:`garage_mj.grid.image`).
BLOCK_COLOURS = _BLOCK_COLOURS
TILE_MARKERS = {Tile.DEAD_END: "s", Tile.CURVE: "o", Tile.T: "^", Tile.CROSS: "P", Tile.ISOLATED: "x"}


class PlotError(GarageMJError, ValueError):
    """The data for a figure is missing or unusable (no runs, no monitor log, no garages)."""


# -- convergence ----------------------------------------------------------------------------------
def read_monitor(path: str | Path) -> np.ndarray:
    """Episode returns from an SB3 ``monitor.csv`` (or a run folder holding one)."""
    p = Path(path)
    if p.is_dir():
        p = p / "monitor.csv"
    if not p.exists():
        raise PlotError(f"{path}: no monitor.csv; pass a run folder written by garage-mj train")
    lines = [ln for ln in p.read_text().splitlines() if ln and not ln.startswith("#")]
    if not lines or not lines[0].startswith("r,"):
        raise PlotError(f"{p} is not an SB3 monitor log (expected a header r,l,t)")
    try:
        return np.array([float(ln.split(",")[0]) for ln in lines[1:]], dtype=float)
    except ValueError:
        raise PlotError(f"{p}: a row does not start with a number; the log is damaged") from None


def _run_map(run: Path) -> str:
    manifest = run / "run.json" if run.is_dir() else run.parent / "run.json"
    try:
        return str(json.loads(manifest.read_text())["map"])
    except (OSError, ValueError, KeyError):
        return run.name if run.is_dir() else run.parent.name


def mean_ci(curves: Sequence[np.ndarray], confidence: float = CONFIDENCE) -> tuple[np.ndarray, np.ndarray]:
    """Per-episode mean over curves (cut to the shortest) and the half-width of its t-interval.

    With a single curve the half-width is zero (no spread to estimate).
    """
    from scipy.stats import t

    n_ep = min(len(c) for c in curves)
    data = np.stack([np.asarray(c[:n_ep], dtype=float) for c in curves])
    mean = data.mean(axis=0)
    n = data.shape[0]
    if n < 2:
        return mean, np.zeros_like(mean)
    sem = data.std(axis=0, ddof=1) / np.sqrt(n)
    return mean, t.ppf(0.5 + confidence / 2, n - 1) * sem


def _smooth(x: np.ndarray, window: int) -> np.ndarray:
    if window <= 1 or len(x) < window:
        return x
    c = np.cumsum(np.insert(x, 0, 0.0))
    head = c[1:window] / np.arange(1, window)  # growing window at the start: no lag, no padding
    return np.concatenate([head, (c[window:] - c[:-window]) / window])


def convergence(runs: Sequence[str | Path], out: str | Path, smooth: int = 1) -> Path:
    """Return vs episode per map: mean over its runs and a 95% confidence band; writes ``out``."""
    if not runs:
        raise PlotError("no runs given; pass run folders written by garage-mj train")
    by_map: dict[str, list[np.ndarray]] = {}
    for run in runs:
        returns = read_monitor(run)
        if len(returns) == 0:
            raise PlotError(f"{run}: the monitor log has no finished episode yet")
        by_map.setdefault(_run_map(Path(run)), []).append(_smooth(returns, smooth))
    cols = min(MAX_PANEL_COLUMNS, len(by_map))
    rows = -(-len(by_map) // cols)
    fig, axes = plt.subplots(rows, cols, figsize=(5 * cols, 3.6 * rows), squeeze=False)
    for ax in axes.flat[len(by_map):]:
        ax.set_visible(False)
    for ax, (name, curves) in zip(axes.flat, by_map.items()):  # maps in the order given
        mean, half = mean_ci(curves)
        ep = np.arange(len(mean))
        ax.fill_between(ep, mean - half, mean + half, color="#9ecae1", alpha=0.6, lw=0,
                        label=f"{CONFIDENCE:.0%} CI" if len(curves) > 1 else None)
        ax.plot(ep, mean, color="#08519c", lw=1.2, label=f"mean of {len(curves)} run(s)")
        ax.set_title(name)
        ax.set_xlabel("episode")
        ax.set_ylabel("return" + (f" ({smooth}-episode mean)" if smooth > 1 else ""))
        ax.grid(alpha=0.3)
        ax.legend(loc="lower right", fontsize=8)
    fig.tight_layout()
    return _save(fig, out)


# -- driver training ------------------------------------------------------------------------------
def driver_curve(runs: Sequence[str | Path], out: str | Path) -> Path:
    """Validation success (solid) and agreement with the oracle (dashed) per iteration, vs the states
    trained on, one line pair per ``train-driver`` run folder (or its ``curve.csv``); writes ``out``."""
    import csv

    if not runs:
        raise PlotError("no runs given; pass run folders written by garage-mj train-driver")
    fig, ax = plt.subplots(figsize=(6.4, 4.0))
    for k, run in enumerate(runs):
        path = Path(run)
        path = path / "curve.csv" if path.is_dir() else path
        try:
            with path.open(newline="") as f:
                rows = list(csv.DictReader(f))
        except OSError as exc:
            raise PlotError(f"{path}: cannot read the training curve ({exc.strerror}); is it a train-driver run?") from None
        rows = [r for r in rows if r.get("val_success") not in (None, "")]
        if not rows:
            raise PlotError(f"{path}: no finished iteration with a validation figure yet")
        states = [int(r["states"]) for r in rows]
        colour = f"C{k % 10}"
        label = path.parent.name
        ax.plot(states, [100 * float(r["val_success"]) for r in rows], "-o", color=colour, lw=1.4, ms=4,
                label=f"{label}: validation success")
        ax.plot(states, [100 * float(r["agreement"]) for r in rows], "--", color=colour, lw=1.0,
                label=f"{label}: agreement with the oracle")
    ax.set_xlabel("states trained on (oracle-labelled)")
    ax.set_ylabel("%")
    ax.set_ylim(0, 102)
    ax.grid(alpha=0.3)
    ax.legend(loc="lower right", fontsize=7)
    ax.set_title("learned driver: DAgger iterations")
    fig.tight_layout()
    return _save(fig, out)


# -- heatmap --------------------------------------------------------------------------------------
def heatmap_counts(points: np.ndarray, bin: float = BIN) -> np.ndarray:
    """Counts in a (coverage bins) x (difficulty bins) array over [0, 1]^2; 1.0 falls in the last bin."""
    n = round(1 / bin)
    counts = np.zeros((n, n), dtype=int)
    if len(points):
        idx = np.clip((np.asarray(points) / bin).astype(int), 0, n - 1)
        np.add.at(counts, (idx[:, 1], idx[:, 0]), 1)
    return counts


#: The difficulty on a heatmap's x axis: the paper's (its figure) or the route difficulty.
HEATMAP_X = {"paper": "difficulty λ", "route": "route difficulty (expected failure rate)"}


def heatmap(points: np.ndarray, out: str | Path, title: str = "", metric: str = "paper") -> Path:
    """Difficulty (x) vs coverage (y) of ``points`` (N x 2: difficulty, coverage), count per 0.1 cell;
    ``metric`` names the difficulty: ``"paper"`` (the paper's figure) or ``"route"``."""
    if metric not in HEATMAP_X:
        raise ValueError(f"metric must be one of {', '.join(HEATMAP_X)}, got {metric!r}")
    counts = heatmap_counts(points)
    n = counts.shape[0]
    fig, ax = plt.subplots(figsize=(5.4, 4.6))
    im = ax.imshow(counts, origin="lower", extent=(0, 1, 0, 1), cmap="Blues", aspect="equal",
                   vmin=0, vmax=max(1, counts.max()))
    top = counts.max()
    for (i, j), c in np.ndenumerate(counts):
        if c:
            ax.text((j + 0.5) * BIN, (i + 0.5) * BIN, str(c), ha="center", va="center", fontsize=7,
                    color="white" if c > top / 2 else "black")
    ticks = np.linspace(0, 1, n + 1)
    ax.set_xticks(ticks)
    ax.set_yticks(ticks)
    ax.tick_params(labelsize=7)
    ax.set_xlabel(HEATMAP_X[metric])
    ax.set_ylabel("coverage δ")
    ax.set_title(f"{title}  (n = {len(points)})" if title else f"n = {len(points)}")
    from matplotlib.ticker import MaxNLocator

    fig.colorbar(im, ax=ax, label="garages", ticks=MaxNLocator(integer=True))
    fig.tight_layout()
    return _save(fig, out)


# -- one garage -----------------------------------------------------------------------------------
def garage_png(garage: Garage, path: str | Path, title: str | None = None) -> Path:
    """Top-down picture of ``garage``: block colours, a legend, and its road graph on top."""
    grid = garage.grid
    h, w = grid.shape
    cmap = ListedColormap([BLOCK_COLOURS[Block(i)] for i in range(NUM_CODES)])
    fig, ax = plt.subplots(figsize=(0.5 * w + 3.2, 0.5 * h + 0.8))
    ax.imshow(grid, cmap=cmap, vmin=-0.5, vmax=NUM_CODES - 0.5, interpolation="nearest")
    ax.set_xticks(np.arange(-0.5, w, 1), minor=True)
    ax.set_yticks(np.arange(-0.5, h, 1), minor=True)
    ax.grid(which="minor", color="white", lw=0.5)
    ax.tick_params(which="minor", length=0)
    ax.set_xticks(range(w))
    ax.set_yticks(range(h))
    ax.tick_params(labelsize=7)
    roads = analyse(grid)
    for (r, c), mask in roads.masks.items():
        for d, (dr, dc) in enumerate(DELTAS[:4]):
            if mask >> d & 1 and (dr, dc) in ((0, 1), (1, 0)):  # each edge once: east and south
                ax.plot([c, c + dc], [r, r + dr], color="#ffd700", lw=2, solid_capstyle="round", zorder=2)
    for tile, marker in TILE_MARKERS.items():
        cells = [p for p, t in roads.tiles.items() if t == tile]
        if cells:
            rr, cc = zip(*cells)
            ax.scatter(cc, rr, marker=marker, s=36, color="#ffd700", edgecolors="black", lw=0.6, zorder=3,
                       label=f"{tile.name.lower().replace('_', ' ')} node")
    handles = [Patch(color=BLOCK_COLOURS[b], label=f"{int(b)} {b.name}") for b in Block]
    node_handles, _ = ax.get_legend_handles_labels()
    ax.legend(handles=handles + node_handles, loc="upper left", bbox_to_anchor=(1.01, 1.0), fontsize=7,
              frameon=False)
    ax.set_title(title or f"{garage.name} ({h}x{w}, six-stall axis {garage.six_stall_axis})", fontsize=9)
    fig.tight_layout()
    return _save(fig, path)


def _save(fig, out: str | Path) -> Path:
    out = Path(out)
    out.parent.mkdir(parents=True, exist_ok=True)
    fmt = out.suffix.lstrip(".").lower() or "png"
    try:
        buf = io.BytesIO()
        fig.savefig(buf, dpi=DPI, format=fmt)
        atomic_write(out, buf.getvalue())
    except OSError as exc:
        raise PlotError(f"cannot write {out}: {exc.strerror}") from None
    except ValueError as exc:  # unknown file extension
        raise PlotError(f"cannot write {out}: {exc}") from None
    finally:
        plt.close(fig)
    return out
