"""The regression figure of cruise results: success rate against difficulty (paper Fig. "Linear regression").

The numbers (Pearson r, the least-squares line, the paper's table) are computed in
:mod:`garage_mj.driving.difficulty.regression`, numpy only, so the cruise runner writes them without matplotlib;
:func:`regression_plot` draws them against the paper's difficulty next to the paper's 16 garages, or
(``metric="route"``) against the route difficulty next to the line a perfectly calibrated one would
follow (success = 100 (1 - route difficulty): it is the expected failure rate).
"""

from __future__ import annotations

import io
import math
from collections.abc import Sequence
from pathlib import Path

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402

from garage_mj.core.fsutil import atomic_write  # noqa: E402
from garage_mj.driving.difficulty.regression import (  # noqa: E402
    PAPER_TABLE,
    flat_note,
    paper_regression,
    regression,
    too_few,
)

#: The difficulties a figure can put on its x axis, and the axis label and default title of each.
METRICS = {"paper": ("difficulty λ", "Success rate vs. garage difficulty"),
           "route": ("route difficulty (expected failure rate)", "Success rate vs. route difficulty")}


def regression_plot(
    difficulty: Sequence[float],
    success: Sequence[float],
    out: str | Path,
    title: str | None = None,
    reference: bool = True,
    metric: str = "paper",
) -> Path:
    """Scatter of success % against difficulty with the fitted line (paper Fig. "Linear regression").

    ``metric``: ``"paper"`` (the paper's difficulty λ) or ``"route"`` (the route difficulty; then
    ``difficulty`` holds route difficulties). ``reference`` adds in grey the paper's 16 garages and line
    (paper), or the calibrated line success = 100 (1 - x) (route). Over fewer garages than
    :data:`~garage_mj.driving.difficulty.regression.MIN_GARAGES` the points are drawn without r or a line; when
    every garage has the same success rate (a tiny garage whose tests all succeed) the figure says so
    (:func:`~garage_mj.driving.difficulty.regression.flat_note`) instead of drawing a flat "fit" that looks like a finding.
    """
    if metric not in METRICS:
        raise ValueError(f"metric must be one of {', '.join(METRICS)}, got {metric!r}")
    fit = regression(difficulty, success)
    fig, ax = plt.subplots(figsize=(5.5, 4.0), dpi=120)
    xs = np.linspace(0.0, 1.0, 50)
    if reference and metric == "route":
        ax.plot(xs, 100 * (1 - xs), c="0.65", lw=1, ls="--", label="calibrated: success = 100 (1 - x)")
    elif reference:
        ref = paper_regression()
        table = np.array(PAPER_TABLE)
        ax.scatter(table[:, 2], table[:, 3], s=18, c="0.65", marker="s", label=f"paper (r = {ref.r:.3f})")
        ax.plot(xs, ref.slope * xs + ref.intercept, c="0.65", lw=1, ls="--")
    flat = flat_note(success)
    if not fit.reportable:  # no r and no line through 2-4 points: they would mislead
        label = f"this run: {too_few(fit.n)}"
    elif flat:
        label = f"this run (n = {fit.n}): no r, no line"
    elif math.isnan(fit.r):
        label = f"this run (n = {fit.n})"
    else:
        label = f"this run (r = {fit.r:.3f}, n = {fit.n})"
    ax.scatter(difficulty, success, s=22, c="tab:blue", label=label)
    if flat and fit.reportable:
        ax.text(0.98, 0.72, flat, transform=ax.transAxes, ha="right", va="center", fontsize=8,
                bbox={"boxstyle": "round", "fc": "white", "ec": "tab:blue", "alpha": 0.9})
    elif fit.reportable and not math.isnan(fit.slope):
        ax.plot(xs, fit.slope * xs + fit.intercept, c="tab:blue", lw=1.5,
                label=f"y = {fit.slope:.1f} x + {fit.intercept:.1f}")
    xlabel, default_title = METRICS[metric]
    ax.set(xlabel=xlabel, ylabel="success rate [%]", xlim=(0, 1), ylim=(-5, 105), title=title or default_title)
    ax.grid(alpha=0.3)
    ax.legend(fontsize=8, loc="lower left")
    out = Path(out)
    out.parent.mkdir(parents=True, exist_ok=True)
    buf = io.BytesIO()
    fig.savefig(buf, format="png", bbox_inches="tight")
    plt.close(fig)
    return atomic_write(out, buf.getvalue())

