"""One comparison for the vector env tests: a GarageGenVecEnv against SB3's DummyVecEnv over single envs."""

from __future__ import annotations

from collections.abc import Callable, Sequence
from typing import Any

import numpy as np

INFO_KEYS = ("usable", "coverage", "difficulty", "stalls", "errors", "TimeLimit.truncated")


def step_alike(vec: Any, ref: Any, one_hot: Callable[[np.ndarray], np.ndarray], steps: int,
               keys: Sequence[str] = INFO_KEYS) -> list[dict[str, Any]]:
    """Seed both with 3 and step them with the same random actions for ``steps`` steps, asserting the same
    observations (``vec``'s through ``one_hot``), rewards, episode ends, final garages, ``keys`` of the infos
    and terminal observations; returns ``vec``'s infos of the episodes that ended."""
    n = vec.num_envs
    vec.seed(3)
    ref.seed(3)
    assert np.array_equal(one_hot(vec.reset()), ref.reset())
    rng = np.random.default_rng(0)
    ended = []
    for _ in range(steps):
        actions = rng.integers(0, 4, n)
        obs, rewards, dones, infos = vec.step(actions)
        obs_r, rewards_r, dones_r, infos_r = ref.step(actions)
        assert np.array_equal(one_hot(obs), obs_r)
        assert np.array_equal(rewards, rewards_r) and np.array_equal(dones, dones_r)
        for i in np.flatnonzero(dones):
            mine, theirs = infos[i], infos_r[i]
            assert np.array_equal(mine["final_garage"].grid, theirs["final_garage"].grid)
            assert mine["final_garage"].six_stall_axis == theirs["final_garage"].six_stall_axis
            for key in keys:
                assert mine[key] == theirs[key], key
            assert np.array_equal(one_hot(mine["terminal_observation"][None])[0], theirs["terminal_observation"])
            ended.append(mine)
    return ended
