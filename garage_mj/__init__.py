"""garage-mj: adverse underground-garage scenarios for automated valet parking, in MuJoCo.

One subpackage per pipeline stage; each imports only from the stages before it
(``tests/test_layout.py`` checks it):

- ``core``: plumbing every stage uses (errors, atomic writes, config loading, backends, geometry).
- ``grid``: the garage as an encoding matrix: block codes, garage model, rules, metrics, map files.
- ``generation``: the painter envs, DQN training, conditioned generation, search, the library.
- ``scene``: the 3D world derived from a garage, computed once per garage as a ``GarageScene``.
- ``export``: writers only: OpenDRIVE, OpenSCENARIO, meshes, preview, asset packs, validators.
- ``driving``: car, sensors, outcomes, actors, the drive env, drivers, cruise tests, hunt.
- ``reporting``: plots, analysis, video, the HTML report, the demo.
- ``testing``: garage-mj in a user's test suite: garages for tests, cruise tests of a driver class with
  an assertion that lists each failure (the ``pytest_garage_mj`` plugin's machinery).
- ``cli``: the ``garage-mj`` command line, thin, on top.

This module keeps the public API (``load_map``, ``evaluate``, ``Garage``, ...; ``evaluate(garage,
route=True)`` adds the route-aware difficulty to the paper's metrics) and registers the
gymnasium ids (``garage_mj/GarageGen-v0``, ``garage_mj/GarageGenCond-v0``, ``garage_mj/GarageDrive-v0``).
"""

from __future__ import annotations

import dataclasses as _dataclasses
import os as _os
from typing import TYPE_CHECKING

# MuJoCo reads MUJOCO_GL once, when it is first imported: default to headless EGL before any import.
_os.environ.setdefault("MUJOCO_GL", "egl")

from garage_mj.core import __version__  # noqa: E402
from garage_mj.core.lazy import lazy_exports
from garage_mj.grid.blocks import Block
from garage_mj.grid.garage import Garage, MapError
from garage_mj.grid.map_io import list_maps, load_map
from garage_mj.grid.metrics import DEFAULT_DIFFICULTY, DifficultyConfig, GarageMetrics, difficulty
from garage_mj.grid.metrics import evaluate as _evaluate_grid

if TYPE_CHECKING:
    from pathlib import Path

    from garage_mj.scene.route_difficulty import RouteDifficulty

#: The route difficulty's public names load on first use, as the stage facades' do: ``import garage_mj``
#: imports no scene module.
__getattr__, _LAZY = lazy_exports(__name__, {"RouteDifficulty": "scene.route_difficulty",
                                             "load_route_model": "scene.route_difficulty",
                                             "route_difficulty": "scene.route_difficulty"})

__all__ = [
    "Block",
    "Garage",
    "GarageMetrics",
    "MapError",
    "__version__",
    "difficulty",
    "evaluate",
    "list_maps",
    "load_map",
    *_LAZY,
]


def evaluate(garage: Garage, config: DifficultyConfig = DEFAULT_DIFFICULTY, *, route: bool = False,
             model: RouteDifficulty | str | Path | None = None) -> GarageMetrics:
    """Every metric of ``garage`` (:func:`garage_mj.grid.metrics.evaluate`: the paper's difficulty, coverage, ...).

    With ``route=True`` (or a ``model``) also its route difficulty, the expected failure rate of a cruise
    test predicted from the planned routes (:func:`garage_mj.scene.route_difficulty.route_difficulty`;
    NaN when no stall has a feasible route), under ``model`` (a ``RouteDifficulty`` or a model file;
    None: the shipped one). It plans every stall, so it costs ~0.1-2 s where the rest costs milliseconds.
    """
    metrics = _evaluate_grid(garage, config)
    if not route and model is None:
        return metrics
    m = model if isinstance(model, __getattr__("RouteDifficulty")) else __getattr__("load_route_model")(model)
    return _dataclasses.replace(metrics, route_difficulty=__getattr__("route_difficulty")(garage, m))


#: Gymnasium id -> entry point; registered once, when the package is imported (no env module loads).
ENV_IDS = {
    "garage_mj/GarageGen-v0": "garage_mj.generation.gen_env:GarageGenEnv",
    "garage_mj/GarageGenCond-v0": "garage_mj.generation.cond_env:GarageGenCondEnv",
    "garage_mj/GarageDrive-v0": "garage_mj.driving.sim.drive_env:GarageDriveEnv",
}


def register_envs() -> None:
    """Register every env id (idempotent)."""
    import gymnasium as gym

    for env_id, entry_point in ENV_IDS.items():
        if env_id not in gym.registry:
            gym.register(id=env_id, entry_point=entry_point)


register_envs()
