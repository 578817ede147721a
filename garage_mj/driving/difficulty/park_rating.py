"""The park difficulty of a park or AVP run's tests: the run's model, and each test's ``park_difficulty`` cell.

:func:`choose_park_model` picks a run's model as :func:`~garage_mj.driving.difficulty.rating.choose_route_model`
picks its route model: the one given, else the driver's shipped one, else the default (fitted on ``park_assist``);
a shipped model is read once per process. The runner fills each new row's ``park_difficulty`` with
:func:`park_difficulty_cell` as the test ends (in the parent process: the model is a few numbers, and a worker
never needs it).
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from garage_mj.driving.sim.outcomes import NOT_DRIVEN
from garage_mj.scene.park_difficulty import (
    DEFAULT_PARK_MODEL,
    SHIPPED_PARK_MODELS,
    ParkDifficulty,
    ParkFeatureError,
    ParkModelError,
    load_park_model,
)


@dataclass(frozen=True)
class ParkModelChoice:
    """The park difficulty model of a park or AVP run and the name it goes by; or none (``model`` None, ``note``)."""

    model: ParkDifficulty | None
    name: str | None = None  # a shipped model's name, a model file, or "given"
    note: str | None = None

    def record(self) -> dict[str, Any]:
        """What ``summary.json`` says of the park difficulty."""
        if self.model is None:
            return {"park_model": None, "park_model_name": None, "park_model_fitted_for": None, "park_note": self.note}
        return {"park_model": self.model.key, "park_model_name": self.name,
                "park_model_fitted_for": list(self.model.fit.get("drivers", [])), "park_note": self.note}


def choose_park_model(park_model: ParkDifficulty | str | Path | bool | None, driver: Any,
                      driver_kwargs: dict[str, Any] | None = None) -> ParkModelChoice:
    """The park difficulty model of a park or AVP run of ``driver``.

    True or None: the shipped model fitted on that driver (:data:`~garage_mj.scene.park_difficulty.SHIPPED_PARK_MODELS`),
    else the default one (fitted on ``park_assist``), whose probabilities are then park_assist's failure rate on the
    test, not this driver's (``note`` says so). A model, a model file or a shipped model's name: that one. False: none.
    """
    if park_model is False:
        return ParkModelChoice(None, note="no park difficulty asked for")
    if park_model is not True and park_model is not None:
        if isinstance(park_model, ParkDifficulty):
            return ParkModelChoice(park_model, "given")
        return ParkModelChoice(load_park_model(park_model), str(park_model))
    own = None if (driver_kwargs or {}).get("model") else driver  # another learned model is not the shipped one
    try:
        for name in SHIPPED_PARK_MODELS:
            model = _shipped(name)
            if own is not None and own in model.fit.get("drivers", []):
                return ParkModelChoice(model, name)
        model = _shipped(DEFAULT_PARK_MODEL)
    except ParkModelError as exc:  # an installation without the shipped models: the run goes on without
        return ParkModelChoice(None, note=f"no park difficulty: {exc}")
    return ParkModelChoice(model, DEFAULT_PARK_MODEL,
                           note=f"no shipped park model was fitted on driver {driver!r}: park_difficulty is the default "
                                f"model's ({', '.join(model.fit.get('drivers', []))}); give --park-model FILE "
                                f"(garage-mj difficulty fit --task park) for the driver's own")


_SHIPPED: dict[str, ParkDifficulty] = {}


def _shipped(name: str) -> ParkDifficulty:
    """A shipped park model, read once per process."""
    if name not in _SHIPPED:
        _SHIPPED[name] = load_park_model(name)
    return _SHIPPED[name]


def park_difficulty_cell(model: ParkDifficulty, row: Mapping[str, Any]) -> Any:
    """A row's ``park_difficulty``: its failure probability under ``model`` (4 digits), or "" for a test not driven
    (infeasible, unproven) or one whose row lacks a feature's cell (a lost test)."""
    if row.get("task") not in ("park", "avp") or row.get("outcome") in NOT_DRIVEN or str(row.get("feasible")) != "1":
        return ""
    try:
        return round(model.of_row(row), 4)
    except ParkFeatureError:
        return ""


__all__ = ["ParkModelChoice", "choose_park_model", "park_difficulty_cell"]
