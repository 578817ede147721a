"""Gymnasium environments of garage-mj, registered once under the ``garage_mj/`` namespace."""

from __future__ import annotations

import gymnasium as gym

ENV_IDS = {
    "garage_mj/GarageGen-v0": "garage_mj.envs.gen_env:GarageGenEnv",
    "garage_mj/GarageGenCond-v0": "garage_mj.envs.cond_env:GarageGenCondEnv",
    "garage_mj/GarageDrive-v0": "garage_mj.envs.drive_env:GarageDriveEnv",
}


def register_envs() -> None:
    """Register every env id (idempotent)."""
    for env_id, entry_point in ENV_IDS.items():
        if env_id not in gym.registry:
            gym.register(id=env_id, entry_point=entry_point)


register_envs()
