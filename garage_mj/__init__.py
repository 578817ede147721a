"""garage-mj: adverse underground-garage scenarios for automated valet parking, in MuJoCo.

Stages, one module each: maps -> garage model -> rules/road graph/metrics -> generation env ->
training and library -> exporters -> cruise testbed -> reports.
"""

from __future__ import annotations

import os as _os

# MuJoCo reads MUJOCO_GL once, when it is first imported: default to headless EGL before any import.
_os.environ.setdefault("MUJOCO_GL", "egl")

from garage_mj.grid.blocks import Block  # noqa: E402
from garage_mj.grid.garage import Garage, MapError
from garage_mj.grid.map_io import list_maps, load_map
from garage_mj.grid.metrics import GarageMetrics, difficulty, evaluate

__version__ = "0.1.0"

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
