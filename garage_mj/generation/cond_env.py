"""GarageGenCondEnv: the painter MDP conditioned on a target difficulty (and coverage) band.

The control-pcgrl idea for garages: every episode carries a target band ``[lo, hi]`` of
difficulty (and, optionally, of coverage) that the agent sees in its observation, next to the
difficulty of what it has painted so far. On top of the painter's own reward terms it gets

* shaping every step: ``shaping * (dist_before - dist_after)``, where ``dist`` is how far the
  current (partial) garage's difficulty and coverage lie outside the bands, and
* at the end of a usable episode: ``band_bonus`` when the garage lands inside every band, else
  ``-distance_penalty * dist``.

The band is drawn from the episode's seed (uniform over ``difficulty_range``, ``band_width``
wide) unless ``reset(options={"difficulty": (lo, hi), "coverage": (lo, hi)})`` fixes it, which
is how ``garage-mj generate`` asks for a band. Registered as ``garage_mj/GarageGenCond-v0``.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any

import numpy as np
from gymnasium import spaces

from garage_mj.core.config import ConfigError, load_config
from garage_mj.generation.gen_env import GarageGenEnv
from garage_mj.grid.metrics import difficulty

N_COND = 5  # observation entries appended: difficulty lo, hi, current difficulty, coverage lo, hi


@dataclass(frozen=True)
class ConditionConfig:
    """Target bands drawn per episode and the reward for landing in them (TOML-loadable)."""

    band_width: float = 0.1  # [difficulty] width of a drawn difficulty band
    difficulty_lo: float = 0.0  # drawn bands lie inside [difficulty_lo, difficulty_hi]
    difficulty_hi: float = 1.0  # (the map's admissible range where known)
    coverage_share: float = 0.5  # share of episodes that also draw a coverage band (else [0, 1])
    coverage_width: float = 0.2  # [coverage] width of a drawn coverage band
    coverage_lo: float = 0.3  # drawn coverage bands lie inside [coverage_lo, coverage_hi]
    coverage_hi: float = 1.0
    band_bonus: float = 100.0  # a usable garage inside every band
    distance_penalty: float = 100.0  # per unit of distance to the bands, for a usable garage outside (<= exit bonus)
    shaping: float = 20.0  # per unit of distance closed during the episode

    def __post_init__(self) -> None:
        for name in ("band_width", "coverage_width"):
            v = getattr(self, name)
            if not 0.0 < v <= 1.0:
                raise ConfigError(f"ConditionConfig: {name} must be in (0, 1], got {v!r}")
        for lo, hi in (("difficulty_lo", "difficulty_hi"),
                       ("coverage_lo", "coverage_hi")):
            a, b = getattr(self, lo), getattr(self, hi)
            if not 0.0 <= a <= b <= 1.0:
                raise ConfigError(f"ConditionConfig: need 0 <= {lo} <= {hi} <= 1, got {a!r}, {b!r}")
        if not 0.0 <= self.coverage_share <= 1.0:
            raise ConfigError(f"ConditionConfig: coverage_share must be in [0, 1], got {self.coverage_share!r}")
        for name in ("band_bonus", "distance_penalty", "shaping"):
            v = getattr(self, name)
            if not math.isfinite(v) or v < 0:
                raise ConfigError(f"ConditionConfig: {name} must be a finite number >= 0, got {v!r}")


def band_distance(x: float, band: tuple[float, float]) -> float:
    """How far ``x`` lies outside ``band`` (0 inside)."""
    lo, hi = band
    return max(lo - x, 0.0, x - hi)


def _band(value: Any, name: str) -> tuple[float, float]:
    try:
        lo, hi = (float(v) for v in value)
    except (TypeError, ValueError):
        raise ValueError(f"{name} band must be a pair (lo, hi), got {value!r}") from None
    if not 0.0 <= lo <= hi <= 1.0:
        raise ValueError(f"{name} band must satisfy 0 <= lo <= hi <= 1, got ({lo}, {hi})")
    return lo, hi


class GarageGenCondEnv(GarageGenEnv):
    """The painter of :class:`GarageGenEnv` with a target band in its observation.

    Args:
        condition: :class:`ConditionConfig` or a dict of its fields.
        everything else: as :class:`GarageGenEnv`.

    The observation is the painter's, followed by difficulty lo, hi, the current garage's
    difficulty, and coverage lo, hi (the current coverage is already in the painter's part).
    ``info`` adds ``target_difficulty``, ``target_coverage`` and ``in_band``.
    """

    def __init__(self, map="tiny_7x11", view_size: int = 7, max_errors: int = 10, reward=None,
                 six_stall_axis=None, max_steps: int | None = None, render_mode: str | None = None,
                 condition: ConditionConfig | dict[str, Any] | None = None) -> None:
        super().__init__(map=map, view_size=view_size, max_errors=max_errors, reward=reward,
                         six_stall_axis=six_stall_axis, max_steps=max_steps, render_mode=render_mode)
        self.condition = condition if isinstance(condition, ConditionConfig) else load_config(ConditionConfig, condition)
        base = self.observation_space
        low = np.concatenate([base.low, np.zeros(N_COND, dtype=np.float32)])
        high = np.concatenate([base.high, np.ones(N_COND, dtype=np.float32)])
        self.observation_space = spaces.Box(low, high, dtype=np.float32)
        self.target_difficulty = (0.0, 1.0)
        self.target_coverage = (0.0, 1.0)
        self._difficulty = 0.0
        self._dist = 0.0

    def reset(self, *, seed: int | None = None, options: dict[str, Any] | None = None):
        options = dict(options or {})
        want_d, want_c = options.pop("difficulty", None), options.pop("coverage", None)
        super().reset(seed=seed, options=options)
        cfg, rng = self.condition, self.np_random
        # draw both bands every reset so the stream of draws does not depend on the options
        lo = rng.uniform(cfg.difficulty_lo, max(cfg.difficulty_lo, cfg.difficulty_hi - cfg.band_width))
        drawn_d = (lo, min(1.0, lo + cfg.band_width))
        lo = rng.uniform(cfg.coverage_lo, max(cfg.coverage_lo, cfg.coverage_hi - cfg.coverage_width))
        drawn_c = (lo, min(1.0, lo + cfg.coverage_width)) if rng.random() < cfg.coverage_share else (0.0, 1.0)
        self.target_difficulty = _band(want_d, "difficulty") if want_d is not None else drawn_d
        self.target_coverage = _band(want_c, "coverage") if want_c is not None else drawn_c
        self._difficulty = self._current_difficulty()
        self._dist = self._distance()
        return self._obs(), self._info()

    def _advance(self, action) -> tuple[float, bool, bool]:
        """The painter's step, plus the shaping toward the bands and, when a usable episode ends, the band
        bonus or the distance penalty: the conditioned reward in one place, for ``step`` and for
        :class:`~garage_mj.generation.vec_env.GarageGenVecEnv`."""
        reward, terminated, truncated = super()._advance(action)
        cfg = self.condition
        self._difficulty = self._current_difficulty()
        dist = self._distance()
        reward += cfg.shaping * (self._dist - dist)
        self._dist = dist
        if (terminated or truncated) and self.connected and self.errors <= self.max_errors:
            reward += cfg.band_bonus if dist == 0.0 else -cfg.distance_penalty * dist
        return float(reward), terminated, truncated

    # -- internals -------------------------------------------------------------------------------
    def _current_difficulty(self) -> float:
        t = self._tracker
        return difficulty(t.mean_y(), t.mean_x())

    def _distance(self) -> float:
        return band_distance(self._difficulty, self.target_difficulty) + band_distance(
            self._coverage(), self.target_coverage)

    def _fill_condition(self, out: np.ndarray) -> None:
        """The :data:`N_COND` values after the painter's: difficulty lo, hi, current difficulty, coverage lo, hi."""
        out[0], out[1] = self.target_difficulty
        out[2] = self._difficulty
        out[3], out[4] = self.target_coverage

    def _obs(self) -> np.ndarray:
        base = super()._obs()
        obs = np.empty(base.shape[0] + N_COND, dtype=np.float32)
        obs[: base.shape[0]] = base
        self._fill_condition(obs[base.shape[0] :])
        return obs

    def _codes_obs(self, out: np.ndarray) -> None:
        """The painter's codes observation (k * k codes, 7 state values), then the :data:`N_COND` values."""
        super()._codes_obs(out)
        self._fill_condition(out[-N_COND:])

    def _info(self) -> dict[str, Any]:
        info = super()._info()
        if hasattr(self, "target_difficulty"):
            info["target_difficulty"] = self.target_difficulty
            info["target_coverage"] = self.target_coverage
            info["in_band"] = bool(info["usable"] and self._dist == 0.0)
        return info
