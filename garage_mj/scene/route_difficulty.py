"""The route-aware difficulty: how likely a cruise test is to fail, from its planned route alone.

A :class:`RouteDifficulty` is a logistic regression on the route features of
:mod:`garage_mj.scene.route_features`, with every coefficient constrained to be >= 0: each feature
is oriented so that larger is harder, so the difficulty is monotone in each of them and its
coefficients read as "how much this makes a drive harder" (on standardized features: one standard
deviation of the fitting data). The difficulty of a test is the fitted failure probability

    p = 1 / (1 + exp(-(b0 + sum_k w_k (x_k - mean_k) / scale_k))),   w_k >= 0,

and the route difficulty of a garage is its mean over the garage's tests as cruise draws them (a
uniform target stall, success counted over feasible stalls): the expected failure rate of a
driver like the ones it was fitted on, in [0, 1].

:func:`fit` fits one with SciPy's bounded L-BFGS-B on the penalized log-likelihood (a fixed
L2 penalty ``l2`` on the standardized weights; nothing is tuned on held-out data). The fitted model
is a small JSON file (:meth:`RouteDifficulty.save` / :func:`load_route_model`) that names its
fitting data; the shipped one is ``models/difficulty/route.json``, fitted by
``garage-mj difficulty fit`` on the cruise runs it names (its ``fit_data`` CSV ships beside it).
"""

from __future__ import annotations

import hashlib
import json
import math
from collections.abc import Sequence
from dataclasses import dataclass, field
from importlib import resources
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np

from garage_mj.core.errors import GarageMJError
from garage_mj.core.fsutil import write_json
from garage_mj.scene.route_features import FEATURES, garage_features

if TYPE_CHECKING:
    from garage_mj.grid.garage import Garage
    from garage_mj.scene.garage_scene import GarageScene

FORMAT = "garage-mj route difficulty"
VERSION = 1
SHIPPED = "route.json"  # in the package data folder garage_mj.models/difficulty
#: the shipped models by name (``--route-model learned``): the default, fitted on the three drivers' runs, and the
#: shipped learned driver's own (its failures follow other features than the rule-based drivers')
SHIPPED_MODELS = {"route": SHIPPED, "learned": "learned.json"}
L2 = 1.0  # penalty on the standardized weights (the fit's only setting; fixed, never tuned)


class RouteModelError(GarageMJError):
    """A route difficulty model file is missing, unreadable or not one this version reads."""


@dataclass(frozen=True)
class RouteDifficulty:
    """A fitted route difficulty: per-feature mean, scale and weight (>= 0), and the intercept."""

    features: tuple[str, ...]
    mean: tuple[float, ...]
    scale: tuple[float, ...]
    weights: tuple[float, ...]
    intercept: float
    fit: dict[str, Any] = field(default_factory=dict)  # how it was fitted: data, drivers, tests, figures

    def test_probability(self, feats: dict[str, float] | Sequence[dict[str, float]]) -> float | np.ndarray:
        """Failure probability of one test's features (a float) or of a list of them (an array)."""
        one = isinstance(feats, dict)
        rows = [feats] if one else list(feats)
        x = np.array([[r[k] for k in self.features] for r in rows], dtype=float).reshape(len(rows), -1)
        z = self.intercept + ((x - np.array(self.mean)) / np.array(self.scale)) @ np.array(self.weights)
        p = 1.0 / (1.0 + np.exp(-z))
        return float(p[0]) if one else p

    def of_features(self, per_stall: dict[int, dict[str, float] | None]) -> float:
        """A garage's route difficulty from :func:`~garage_mj.scene.route_features.garage_features` (NaN: no feasible stall)."""
        rows = [f for f in per_stall.values() if f is not None]
        if not rows:
            return math.nan
        value = float(np.mean(self.test_probability(rows)))
        if math.isnan(value):  # never passed on: NaN means "no feasible stall", and this garage has some
            raise RouteModelError(f"route difficulty model {self.key} gives NaN for a garage with feasible stalls; "
                                  "fit it again with garage-mj difficulty fit")
        return value

    @property
    def key(self) -> str:
        """12 hex digits naming the fitted parameters: stored values are only ever read back for the same model."""
        params = [list(self.features), list(self.mean), list(self.scale), list(self.weights), self.intercept]
        return hashlib.sha256(json.dumps(params).encode()).hexdigest()[:12]

    def coefficients(self) -> list[tuple[str, float]]:
        """(feature, weight) largest first: what makes a route hard, per standard deviation."""
        return sorted(zip(self.features, self.weights, strict=True), key=lambda fw: -fw[1])

    def describe(self) -> str:
        """The formula and its weights, one feature a line, largest weight first."""
        lines = [f"route difficulty = P(fail) = sigmoid({self.intercept:+.3f} + sum w * (x - mean) / scale)"]
        for name, w in self.coefficients():
            i = self.features.index(name)
            lines.append(f"  {name:<15} w = {w:6.3f}   mean {self.mean[i]:8.3f}   scale {self.scale[i]:7.3f}")
        return "\n".join(lines)

    # -- file ---------------------------------------------------------------------------------------
    def to_dict(self) -> dict[str, Any]:
        return {"format": FORMAT, "version": VERSION, "features": list(self.features), "mean": list(self.mean),
                "scale": list(self.scale), "weights": list(self.weights), "intercept": self.intercept,
                "fit": self.fit}

    def save(self, path: str | Path) -> None:
        path = Path(path)
        path.parent.mkdir(parents=True, exist_ok=True)
        write_json(path, self.to_dict(), indent=1)


def load_route_model(path: str | Path | None = None) -> RouteDifficulty:
    """The model in ``path`` (a file of :meth:`RouteDifficulty.save`), the shipped one when None, or a shipped
    one by its name in :data:`SHIPPED_MODELS` (when no file of that name exists)."""
    name = "route" if path is None else str(path) if str(path) in SHIPPED_MODELS and not Path(path).exists() else None
    if name is not None:
        ref = resources.files("garage_mj.models") / "difficulty" / SHIPPED_MODELS[name]
        text, where = ref.read_text(), f"the shipped route difficulty model {name!r}"
    else:
        p = Path(path)
        if not p.is_file():
            raise RouteModelError(f"route difficulty model {p} does not exist; fit one with garage-mj difficulty fit "
                                  "or leave it out to use the shipped one")
        try:
            text = p.read_text(encoding="utf-8")
        except (OSError, UnicodeDecodeError) as exc:
            raise RouteModelError(f"cannot read route difficulty model {p} ({exc}); fit it again") from None
        where = str(p)
    try:
        d = json.loads(text)
    except ValueError:
        raise RouteModelError(f"{where} is not valid JSON; fit it again with garage-mj difficulty fit") from None
    if not isinstance(d, dict) or d.get("format") != FORMAT:
        raise RouteModelError(f"{where} is not a route difficulty model; fit one with garage-mj difficulty fit")
    if d.get("version") != VERSION:
        raise RouteModelError(f"{where} is version {d.get('version')!r}; this garage-mj reads version {VERSION}: "
                              "fit it again")
    try:
        feats = tuple(str(f) for f in d["features"])
        unknown = [f for f in feats if f not in FEATURES]
        if unknown:
            raise RouteModelError(f"{where} uses unknown route features {unknown}; fit it again with this garage-mj")
        vals = [tuple(float(v) for v in d[k]) for k in ("mean", "scale", "weights")]
        intercept = float(d["intercept"])
    except (KeyError, TypeError, ValueError):
        raise RouteModelError(f"{where} is damaged (features, mean, scale, weights, intercept); fit it again") from None
    _check_values(where, feats, dict(zip(("mean", "scale", "weights"), vals, strict=True)), intercept)
    return RouteDifficulty(feats, *vals, intercept, dict(d.get("fit", {})))


def _check_values(where: str, feats: tuple[str, ...], vals: dict[str, tuple[float, ...]], intercept: float) -> None:
    """Refuse a model whose numbers cannot give a difficulty: no features, a NaN or infinite value, a
    length that is not the features', a scale <= 0 or a negative weight (one line naming the key)."""
    if not feats:
        raise RouteModelError(f"{where}: its features are empty; fit it again with garage-mj difficulty fit")
    for key, values in (*vals.items(), ("intercept", (intercept,))):
        if not all(math.isfinite(v) for v in values):
            raise RouteModelError(f"{where}: its {key} holds a NaN or infinite number; fit it again with "
                                  "garage-mj difficulty fit")
        if key != "intercept" and len(values) != len(feats):
            raise RouteModelError(f"{where}: its {key} has {len(values)} values for {len(feats)} features; fit it again")
    if any(s <= 0 for s in vals["scale"]) or any(w < 0 for w in vals["weights"]):
        raise RouteModelError(f"{where} is damaged (a scale <= 0 or a negative weight); fit it again")


def fit(rows: Sequence[dict[str, float]], failed: Sequence[bool], features: Sequence[str] = FEATURES,
        l2: float = L2, info: dict[str, Any] | None = None) -> RouteDifficulty:
    """Fit a route difficulty on per-test feature rows and whether each test failed.

    Maximises the log-likelihood minus ``l2 / 2 * |w|^2`` over standardized features with every
    weight >= 0 (SciPy L-BFGS-B). A feature constant over the data gets weight 0.
    """
    from scipy.optimize import minimize

    y = np.asarray(failed, dtype=float)
    if len(rows) != len(y) or len(y) < 10:
        raise ValueError(f"fitting needs at least 10 tests with an outcome each, got {len(y)}")
    if y.min() == y.max():
        raise ValueError("every fitting test has the same outcome; a difficulty needs both successes and failures")
    feats = tuple(features)
    x = np.array([[r[k] for k in feats] for r in rows], dtype=float)
    mean = x.mean(axis=0)
    scale = x.std(axis=0)
    const = scale < 1e-12
    scale[const] = 1.0
    z = (x - mean) / scale
    n, k = z.shape

    def loss(theta: np.ndarray) -> tuple[float, np.ndarray]:
        b0, w = theta[0], theta[1:]
        t = b0 + z @ w
        # log(1 + e^t) - y t, stable
        nll = np.sum(np.logaddexp(0.0, t) - y * t) / n + 0.5 * l2 * (w @ w) / n
        p = 1.0 / (1.0 + np.exp(-t))
        g = np.concatenate([[np.sum(p - y)], z.T @ (p - y) + l2 * w]) / n
        return float(nll), g

    bounds = [(None, None)] + [(0.0, 0.0) if c else (0.0, None) for c in const]
    prior = math.log(y.mean() / (1 - y.mean()))
    res = minimize(loss, np.concatenate([[prior], np.zeros(k)]), jac=True, method="L-BFGS-B", bounds=bounds)
    if not res.success:
        raise ValueError(f"the fit did not converge: {res.message}")
    fit_info = {"tests": n, "failures": int(y.sum()), "l2": l2, "log_loss": round(float(res.fun), 5), **(info or {})}
    return RouteDifficulty(feats, tuple(mean.tolist()), tuple(scale.tolist()), tuple(float(w) for w in res.x[1:]),
                           float(res.x[0]), fit_info)


def route_difficulty(garage: Garage | GarageScene, model: RouteDifficulty | None = None) -> float:
    """The route difficulty of a garage (NaN when no stall has a feasible route): see the module docstring."""
    from garage_mj.scene.garage_scene import as_scene

    model = model or load_route_model()
    return model.of_features(garage_features(as_scene(garage)))
