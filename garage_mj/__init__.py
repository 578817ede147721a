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

This module keeps the public API (``load_map``, ``evaluate``, ``Garage``, ...) and registers the
gymnasium ids (``garage_mj/GarageGen-v0``, ``garage_mj/GarageGenCond-v0``, ``garage_mj/GarageDrive-v0``).
"""

from __future__ import annotations

import os as _os

# MuJoCo reads MUJOCO_GL once, when it is first imported: default to headless EGL before any import.
_os.environ.setdefault("MUJOCO_GL", "egl")

from garage_mj.core import __version__  # noqa: E402
from garage_mj.grid.blocks import Block
from garage_mj.grid.garage import Garage, MapError
from garage_mj.grid.map_io import list_maps, load_map
from garage_mj.grid.metrics import GarageMetrics, difficulty, evaluate

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
]

#: Gymnasium id -> entry point; registered once, when the package is imported (no env module loads).
ENV_IDS = {
    "garage_mj/GarageGen-v0": "garage_mj.generation.gen_env:GarageGenEnv",
    "garage_mj/GarageGenCond-v0": "garage_mj.generation.cond_env:GarageGenCondEnv",
    "garage_mj/GarageDrive-v0": "garage_mj.driving.drive_env:GarageDriveEnv",
}


def register_envs() -> None:
    """Register every env id (idempotent)."""
    import gymnasium as gym

    for env_id, entry_point in ENV_IDS.items():
        if env_id not in gym.registry:
            gym.register(id=env_id, entry_point=entry_point)


register_envs()
