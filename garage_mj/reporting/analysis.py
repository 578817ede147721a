"""Analysis of cruise results: Pearson r and the linear regression of success rate on difficulty.

The paper validates its difficulty metric with r(difficulty, success %) = -0.638 over 16 garages
of the 13x13 aligned map (SPEC section 5, :data:`PAPER_TABLE`) and a regression plot (paper Fig.
"Linear regression"). :func:`regression` and :func:`regression_plot` reproduce both from any
``(difficulty, success %)`` pairs, numpy only.
"""

from __future__ import annotations

import io
import math
from collections.abc import Sequence
from dataclasses import asdict, dataclass
from pathlib import Path

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402

from garage_mj.core.fsutil import atomic_write  # noqa: E402

#: SPEC section 5: (E[Y], E[X], difficulty, success %) of the paper's 16 garages.
PAPER_TABLE: tuple[tuple[float, float, float, float], ...] = (
    (3.8, 6, 0.033, 86), (3.25, 6, 0.124, 80), (3.6, 5.4, 0.167, 86), (3.167, 4.833, 0.333, 90),
    (3.667, 5.75, 0.097, 84), (3.2, 4.833, 0.328, 86), (3.333, 5, 0.278, 98), (2.8, 4.833, 0.394, 96),
    (4, 5, 0.168, 92), (3, 4.6, 0.4, 86), (2.667, 3.714, 0.603, 78), (3.5, 4.333, 0.362, 98),
    (2.4, 3.667, 0.655, 78), (2.167, 3.429, 0.733, 0), (2.2, 3.333, 0.744, 68), (2.222, 2.8, 0.829, 42),
)
PAPER_R = -0.638  # Pearson r(difficulty, success %) over PAPER_TABLE


@dataclass(frozen=True)
class Regression:
    """Pearson r and the least-squares line ``success = slope * difficulty + intercept`` over n points."""

    r: float  # NaN when either variable is constant or n < 2
    slope: float  # [success % per unit difficulty]
    intercept: float  # [success %]
    n: int

    def as_dict(self) -> dict:
        return {k: (None if isinstance(v, float) and math.isnan(v) else v) for k, v in asdict(self).items()}


def pearson(x: Sequence[float], y: Sequence[float]) -> float:
    """Pearson correlation of ``x`` and ``y``; NaN when either is constant or fewer than 2 points."""
    a, b = np.asarray(x, dtype=float), np.asarray(y, dtype=float)
    if a.shape != b.shape:
        raise ValueError(f"x and y differ in length ({a.size} vs {b.size})")
    if a.size < 2:
        return math.nan
    da, db = a - a.mean(), b - b.mean()
    den = math.sqrt(float(da @ da) * float(db @ db))
    return float(da @ db) / den if den > 0 else math.nan


def regression(difficulty: Sequence[float], success: Sequence[float]) -> Regression:
    """Pearson r and the least-squares line of ``success`` [%] on ``difficulty``."""
    x, y = np.asarray(difficulty, dtype=float), np.asarray(success, dtype=float)
    r = pearson(x, y)
    if x.size < 2 or float(np.ptp(x)) == 0.0:
        return Regression(r, math.nan, math.nan, int(x.size))
    dx = x - x.mean()
    slope = float(dx @ (y - y.mean())) / float(dx @ dx)
    return Regression(r, slope, float(y.mean() - slope * x.mean()), int(x.size))


def paper_regression() -> Regression:
    """The regression over the paper's table (r = -0.638)."""
    table = np.array(PAPER_TABLE)
    return regression(table[:, 2], table[:, 3])


def regression_plot(
    difficulty: Sequence[float],
    success: Sequence[float],
    out: str | Path,
    title: str = "Success rate vs. garage difficulty",
    reference: bool = True,
) -> Path:
    """Scatter of success % against difficulty with the fitted line (paper Fig. "Linear regression").

    ``reference`` adds the paper's 16 garages and line in grey for comparison.
    """
    fit = regression(difficulty, success)
    fig, ax = plt.subplots(figsize=(5.5, 4.0), dpi=120)
    xs = np.linspace(0.0, 1.0, 50)
    if reference:
        ref = paper_regression()
        table = np.array(PAPER_TABLE)
        ax.scatter(table[:, 2], table[:, 3], s=18, c="0.65", marker="s", label=f"paper (r = {ref.r:.3f})")
        ax.plot(xs, ref.slope * xs + ref.intercept, c="0.65", lw=1, ls="--")
    label = f"this run (r = {fit.r:.3f}, n = {fit.n})" if not math.isnan(fit.r) else f"this run (n = {fit.n})"
    ax.scatter(difficulty, success, s=22, c="tab:blue", label=label)
    if not math.isnan(fit.slope):
        ax.plot(xs, fit.slope * xs + fit.intercept, c="tab:blue", lw=1.5,
                label=f"y = {fit.slope:.1f} x + {fit.intercept:.1f}")
    ax.set(xlabel="difficulty λ", ylabel="success rate [%]", xlim=(0, 1), ylim=(-5, 105), title=title)
    ax.grid(alpha=0.3)
    ax.legend(fontsize=8, loc="lower left")
    out = Path(out)
    out.parent.mkdir(parents=True, exist_ok=True)
    buf = io.BytesIO()
    fig.savefig(buf, format="png", bbox_inches="tight")
    plt.close(fig)
    return atomic_write(out, buf.getvalue())
