"""GarageGenVecEnv: N painter envs stepped together as one stable-baselines3 ``VecEnv``.

It paints exactly what N :class:`~garage_mj.generation.gen_env.GarageGenEnv` would under SB3's
``DummyVecEnv`` (same resets, seeds, rewards and garages for the same actions), without the
per-env wrapper calls: the observations are written straight into one (N, D) array and the
info dict (metrics, the final :class:`Garage`) is built only when an episode ends. Each window
cell can be observed as its block code (``window="codes"``, k * k + 7 values; the Q-network's
first layer reads the codes, :class:`~garage_mj.generation.window_net.WindowLayer`), which makes the
replay buffer about 9 times smaller and cheaper to fill and sample than the one-hot rows.
``env_cls=GarageGenCondEnv`` steps the conditioned painter
(:class:`~garage_mj.generation.cond_env.GarageGenCondEnv`) the same way: its rewards, infos and band values.
"""

from __future__ import annotations

import time
from collections.abc import Sequence
from typing import Any

import numpy as np
from gymnasium import spaces
from stable_baselines3.common.vec_env.base_vec_env import VecEnv, VecEnvIndices

from garage_mj.generation.gen_env import GarageGenEnv
from garage_mj.grid.garage import Garage

WINDOWS = ("one_hot", "codes")


class GarageGenVecEnv(VecEnv):
    """``n_envs`` garages of ``map`` painted at once; keyword arguments go to each ``env_cls``.

    Args:
        map: shipped map name, map file path, or a :class:`Garage`.
        n_envs: garages painted together.
        window: ``"one_hot"`` (the single env's observation) or ``"codes"`` (the k x k window as block
            codes 0..NUM_CODES-1, then the same values that follow the single env's window: the 7 state
            values, and for the conditioned env its 5 band values).
        env_cls: :class:`GarageGenEnv` or a subclass that keeps its reward in ``_advance`` and its
            observation in ``_obs``/``_codes_obs``, such as the conditioned
            :class:`~garage_mj.generation.cond_env.GarageGenCondEnv` (``condition=`` then goes to it).

    An episode's last step returns the next episode's first observation, as every SB3 ``VecEnv``
    does; its info holds ``terminal_observation``, ``TimeLimit.truncated``, the single env's info
    (``usable``, ``coverage``, ``difficulty`` ...) and ``final_garage``. Other steps' infos are empty.
    :attr:`seconds` adds up the wall time spent painting.
    """

    def __init__(self, map: str | Garage = "tiny_7x11", n_envs: int = 8, window: str = "one_hot",
                 env_cls: type[GarageGenEnv] = GarageGenEnv, **env_kwargs: Any) -> None:
        if n_envs < 1:
            raise ValueError(f"n_envs must be >= 1, got {n_envs}")
        if window not in WINDOWS:
            raise ValueError(f"window must be one of {', '.join(WINDOWS)}, got {window!r}")
        self.envs = [env_cls(map=map, **env_kwargs) for _ in range(n_envs)]
        first = self.envs[0]
        self.window = window
        space: spaces.Box = first.codes_observation_space() if window == "codes" else first.observation_space
        super().__init__(n_envs, space, first.action_space)
        self._buf = np.zeros((n_envs, *space.shape), dtype=np.float32)
        self._rewards = np.zeros(n_envs, dtype=np.float32)
        self._dones = np.zeros(n_envs, dtype=bool)
        self._actions: np.ndarray | None = None
        self.seconds = 0.0

    # -- VecEnv API -------------------------------------------------------------------------------
    def reset(self) -> np.ndarray:
        t0 = time.perf_counter()
        for i, env in enumerate(self.envs):
            env.reset(seed=self._seeds[i], **self._options[i])
            self._observe(i, env)
        self._reset_seeds()
        self._reset_options()
        self.seconds += time.perf_counter() - t0
        return self._buf.copy()

    def step_async(self, actions: np.ndarray) -> None:
        self._actions = np.asarray(actions)

    def step_wait(self):
        t0 = time.perf_counter()
        actions = self._actions
        assert actions is not None, "step_wait() before step_async()"
        infos: list[dict[str, Any]] = [{} for _ in self.envs]
        for i, env in enumerate(self.envs):
            reward, terminated, truncated = env._advance(actions[i])
            self._rewards[i] = reward
            done = terminated or truncated
            self._dones[i] = done
            if done:
                info = infos[i] = env._info()
                info["final_garage"] = env.garage()
                info["TimeLimit.truncated"] = truncated and not terminated
                self._observe(i, env)
                info["terminal_observation"] = self._buf[i].copy()
                env.reset()
            self._observe(i, env)
        self.seconds += time.perf_counter() - t0
        return self._buf.copy(), self._rewards.copy(), self._dones.copy(), infos

    def close(self) -> None:
        for env in self.envs:
            env.close()

    def get_images(self) -> Sequence[np.ndarray | None]:
        return [env.render() for env in self.envs]

    def get_attr(self, attr_name: str, indices: VecEnvIndices = None) -> list[Any]:
        return [getattr(self.envs[i], attr_name) for i in self._get_indices(indices)]

    def set_attr(self, attr_name: str, value: Any, indices: VecEnvIndices = None) -> None:
        for i in self._get_indices(indices):
            setattr(self.envs[i], attr_name, value)

    def env_method(self, method_name: str, *method_args: Any, indices: VecEnvIndices = None, **method_kwargs: Any) -> list[Any]:
        return [getattr(self.envs[i], method_name)(*method_args, **method_kwargs) for i in self._get_indices(indices)]

    def env_is_wrapped(self, wrapper_class: type, indices: VecEnvIndices = None) -> list[bool]:
        return [False for _ in self._get_indices(indices)]

    # -- internals --------------------------------------------------------------------------------
    def _observe(self, i: int, env: GarageGenEnv) -> None:
        if self.window == "codes":
            env._codes_obs(self._buf[i])
        else:
            self._buf[i] = env._obs()
