"""Pearson r and the linear regression of success rate on difficulty, and the paper's table.

The paper validates its difficulty metric with r(difficulty, success %) = -0.638 over 16 garages
of the 13x13 aligned map (docs/spec.md section 5, :data:`PAPER_TABLE`). :func:`regression` computes the
same numbers from any ``(difficulty, success %)`` pairs, numpy only: the cruise runner writes them
to ``summary.json``; :func:`garage_mj.reporting.analysis.regression_plot` draws them.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import asdict, dataclass

import numpy as np

#: docs/spec.md section 5: (E[Y], E[X], difficulty, success %) of the paper's 16 garages.
PAPER_TABLE: tuple[tuple[float, float, float, float], ...] = (
    (3.8, 6, 0.033, 86), (3.25, 6, 0.124, 80), (3.6, 5.4, 0.167, 86), (3.167, 4.833, 0.333, 90),
    (3.667, 5.75, 0.097, 84), (3.2, 4.833, 0.328, 86), (3.333, 5, 0.278, 98), (2.8, 4.833, 0.394, 96),
    (4, 5, 0.168, 92), (3, 4.6, 0.4, 86), (2.667, 3.714, 0.603, 78), (3.5, 4.333, 0.362, 98),
    (2.4, 3.667, 0.655, 78), (2.167, 3.429, 0.733, 0), (2.2, 3.333, 0.744, 68), (2.222, 2.8, 0.829, 42),
)
PAPER_R = -0.638  # Pearson r(difficulty, success %) over PAPER_TABLE
#: The fewest garages a correlation is reported over: over 2 garages r is always +-1, over 3-4 mostly noise.
MIN_GARAGES = 5


def too_few(n: int) -> str | None:
    """What a report says instead of r over ``n`` garages when they are too few (:data:`MIN_GARAGES`); else None."""
    return f"too few garages ({n}) for a correlation" if n < MIN_GARAGES else None


def flat_note(success: Sequence[float]) -> str | None:
    """Why a run's success rates [%] give no line, when every garage has the same one (``every garage at 100%
    (all its tests succeeded): success does not vary with difficulty here, so there is no line and no r``, in three
    lines for a figure); None when they vary or there is none."""
    values = {round(float(v), 6) for v in success}
    if len(values) != 1:
        return None
    (v,) = values
    return (f"every garage at {v:.0f}%{' (all its tests succeeded)' if v == 100 else ''}:\n"
            "success does not vary with difficulty here,\nso there is no line and no r")


def r_text(r: float | None, n: int) -> str:
    """Pearson r over ``n`` garages as a report prints it: 3 decimals, ``n/a`` when undefined (a constant
    success rate or difficulty), or "too few garages (N) for a correlation"."""
    return too_few(n) or ("n/a" if r is None or math.isnan(r) else f"{r:.3f}")


@dataclass(frozen=True)
class Regression:
    """Pearson r and the least-squares line ``success = slope * difficulty + intercept`` over n points."""

    r: float  # NaN when either variable is constant or n < 2
    slope: float  # [success % per unit difficulty]
    intercept: float  # [success %]
    n: int

    def as_dict(self) -> dict:
        return {k: (None if isinstance(v, float) and math.isnan(v) else v) for k, v in asdict(self).items()}

    @property
    def reportable(self) -> bool:
        """Whether r and the line are over enough garages to report (:data:`MIN_GARAGES`)."""
        return self.n >= MIN_GARAGES

    def as_reported(self) -> dict:
        """:meth:`as_dict` as a summary reports it: r, slope and intercept None over too few garages, and
        ``r_note`` saying so (None otherwise)."""
        out = self.as_dict()
        if not self.reportable:
            out.update(r=None, slope=None, intercept=None)
        return {**out, "r_note": too_few(self.n)}


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


def bootstrap_r(x: Sequence[float], y: Sequence[float], seed: int = 0, resamples: int = 2000,
                level: float = 0.95) -> tuple[float, float]:
    """Percentile bootstrap interval of Pearson r over the (x, y) pairs (SciPy; pairs resampled together); NaN, NaN
    where there is none: fewer than 3 pairs, or resamples whose r is undefined (SciPy's DegenerateDataWarning)."""
    import warnings

    from scipy.stats import DegenerateDataWarning, bootstrap

    a, b = np.asarray(x, dtype=float), np.asarray(y, dtype=float)
    if a.size < 3:
        return math.nan, math.nan
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", DegenerateDataWarning)  # said by the NaN interval it comes with
        res = bootstrap((a, b), lambda u, v: pearson(u, v), paired=True, vectorized=False, n_resamples=resamples,
                        confidence_level=level, method="percentile", rng=np.random.default_rng(seed))
    lo, hi = res.confidence_interval
    return float(lo), float(hi)


def attainable_r(success_pct: Sequence[float], tests: Sequence[int]) -> float:
    """The largest |Pearson r| any per-garage difficulty can expect with these garages' success rates.

    Each garage's success % is measured on ``tests`` tests, so it carries binomial noise of variance
    p (1 - p) / (n - 1) (unbiased, p the measured fraction). Only the rest of the spread between
    garages, their true differences, can follow a difficulty: r(measured, true) = sqrt(1 - mean noise
    variance / variance between garages). A difficulty that knew each garage's true success rate would
    still expect this |r|, no more. NaN with fewer than 2 garages or no spread; 0 when noise explains it all.
    """
    p = np.asarray(success_pct, dtype=float) / 100.0
    n = np.asarray(tests, dtype=float)
    if p.size < 2 or p.shape != n.shape or (n < 2).any():
        return math.nan
    spread = float(p.var(ddof=1))
    if spread <= 0:
        return math.nan
    noise = float(np.mean(p * (1 - p) / (n - 1)))
    return math.sqrt(max(0.0, 1.0 - noise / spread))


def joint_r_bound(r12: float) -> float:
    """The largest |r| one difficulty can have, with the same sign, with two drivers' per-garage success at
    once (say r <= -x with both: harder for both), when those correlate by ``r12`` over the same
    garages: sqrt((1 + r12) / 2).

    r is the cosine of the angle between centred vectors, and angles obey the triangle inequality: if
    a difficulty is within angle t of both (negated) success vectors, they are within 2t of each other,
    so r12 >= cos 2t = 2 r^2 - 1. Two drivers whose success is uncorrelated over the garages (r12 = 0)
    cap any shared difficulty at r -0.707 with both; NaN in, NaN out.
    """
    return math.sqrt((1.0 + r12) / 2.0) if r12 == r12 else math.nan


def bootstrap_attainable_r(success_pct: Sequence[float], tests: Sequence[int], seed: int = 0, resamples: int = 2000,
                           level: float = 0.95) -> tuple[float, float]:
    """Percentile bootstrap interval of :func:`attainable_r` over the garages."""
    p, n = np.asarray(success_pct, dtype=float), np.asarray(tests, dtype=float)
    if p.size < 3:
        return math.nan, math.nan
    rng = np.random.default_rng(seed)
    idx = rng.integers(0, p.size, size=(resamples, p.size))
    values = np.array([attainable_r(p[i], n[i]) for i in idx])
    values = values[~np.isnan(values)]
    if not values.size:
        return math.nan, math.nan
    tail = (1 - level) / 2 * 100
    lo, hi = np.percentile(values, [tail, 100 - tail])
    return float(lo), float(hi)


def auc(score: Sequence[float], positive: Sequence[bool]) -> float:
    """Area under the ROC curve of ``score`` for ``positive`` (ties count half): the Mann-Whitney U / (n+ n-)."""
    from scipy.stats import rankdata

    s, pos = np.asarray(score, dtype=float), np.asarray(positive, dtype=bool)
    n1, n0 = int(pos.sum()), int((~pos).sum())
    if n1 == 0 or n0 == 0:
        return math.nan
    ranks = rankdata(s)
    return float((ranks[pos].sum() - n1 * (n1 + 1) / 2) / (n1 * n0))
