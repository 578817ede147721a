"""GarageGenEnv: the turtle-style painter MDP of docs/spec.md section 3.

A car starts on the ENTRANCE heading inward and moves west/east/north/south. Every cell it
drives onto becomes ROAD and its neighbours are recoloured by the stall rule; the episode ends
at the EXIT (the garage is usable), when errors exceed ``max_errors``, or at the step limit.

The agent sees a k x k one-hot window centred on the car plus the error index, coverage,
connected flag and heading; never its absolute position. A step only touches the target cell,
its neighbours and the road segments through them, so its cost does not grow with the map.
"""

from __future__ import annotations

from typing import Any

import gymnasium as gym
import numpy as np
from gymnasium import spaces

from garage_mj.core.config import load_config
from garage_mj.core.geometry import DELTAS, OPPOSITE
from garage_mj.grid.blocks import AXES, NUM_CODES, STALL_TABLE, Axis, Block
from garage_mj.grid.garage import Garage
from garage_mj.grid.image import grid_image
from garage_mj.grid.map_io import load_map
from garage_mj.grid.metrics import difficulty, utility_values
from garage_mj.grid.reward import RewardConfig
from garage_mj.grid.road_segments import RoadTracker
from garage_mj.grid.rules import stall_code
from garage_mj.grid.text import draw

_FREE, _ROAD, _OBST = int(Block.FREE), int(Block.ROAD), int(Block.OBSTACLE)
_ENTRANCE, _EXIT = int(Block.ENTRANCE), int(Block.EXIT)
_FIXED = (_OBST, _ENTRANCE, _EXIT)
_STALLS = [int(x) for x in STALL_TABLE]
_ROAD_LIKE = (_ROAD, _ENTRANCE, _EXIT)


class GarageGenEnv(gym.Env):
    """Paint a garage's roads and stalls on an initial map (registered as ``garage_mj/GarageGen-v0``).

    Args:
        map: shipped map name, map file path, or a :class:`Garage` whose initial map is used.
        view_size: side k of the observed window (odd).
        max_errors: errors allowed; one more ends the episode as a failure.
        reward: :class:`RewardConfig` or a dict of its fields.
        six_stall_axis: ``"NS"``/``"EW"`` to fix the axis; ``None`` draws it at every reset.
        max_steps: step limit (default 4 * H * W).
        render_mode: ``"ansi"`` returns the grid as text with the car; ``"rgb_array"`` an
            (H * 16, W * 16, 3) uint8 picture of the grid with the car (for ``RecordVideo``).
    """

    metadata = {"render_modes": ["ansi", "rgb_array"], "render_fps": 8}

    def __init__(
        self,
        map: str | Garage = "tiny_7x11",
        view_size: int = 7,
        max_errors: int = 10,
        reward: RewardConfig | dict[str, Any] | None = None,
        six_stall_axis: Axis | None = None,
        max_steps: int | None = None,
        render_mode: str | None = None,
    ) -> None:
        if view_size < 1 or view_size % 2 == 0:
            raise ValueError(f"view_size must be a positive odd number, got {view_size}")
        if max_errors < 0:
            raise ValueError(f"max_errors must be >= 0, got {max_errors}")
        if six_stall_axis is not None and six_stall_axis not in AXES:
            raise ValueError(f"six_stall_axis must be 'NS', 'EW' or None, got {six_stall_axis!r}")
        if render_mode is not None and render_mode not in self.metadata["render_modes"]:
            # TypeError, as gymnasium envs do for an unsupported argument: SB3's make_vec_env first
            # tries render_mode="rgb_array" and falls back on TypeError only
            raise TypeError(f"render_mode must be one of {self.metadata['render_modes']} or None, got {render_mode!r}")
        base = map if isinstance(map, Garage) else load_map(map)
        self.map_name = base.name
        self.initial = base.initial.copy()
        self.h, self.w = self.initial.shape
        self.view_size = view_size
        self.max_errors = max_errors
        self.reward_config = reward if isinstance(reward, RewardConfig) else load_config(RewardConfig, reward)
        self.fixed_axis = six_stall_axis
        self.max_steps = max_steps if max_steps is not None else 4 * self.h * self.w
        self.render_mode = render_mode
        self.entrance, self.exit = base.entrance, base.exit
        self.free0 = int(np.count_nonzero(self.initial == Block.FREE))
        er, ec = self.entrance
        self._inward = next(
            d
            for d, (dr, dc) in enumerate(DELTAS)
            if 0 <= er + dr < self.h and 0 <= ec + dc < self.w and self.initial[er + dr, ec + dc] != Block.OBSTACLE
        )
        p = self._pad = view_size // 2 if view_size > 1 else 1
        self._padded_initial = np.pad(self.initial, p, constant_values=_OBST).astype(np.int8)
        self._eye = np.eye(NUM_CODES, dtype=np.float32)
        n_window = view_size * view_size * NUM_CODES
        self._n_window = n_window
        high = np.ones(n_window + 7, dtype=np.float32)
        high[n_window] = (max_errors + 1) / max(max_errors, 1)  # error index may pass 1 at the end
        self.observation_space = spaces.Box(0.0, high, dtype=np.float32)
        self.action_space = spaces.Discrete(4)
        self.six_stall_axis: Axis = six_stall_axis or "NS"
        self._padded = self._padded_initial.copy()
        self._tracker0 = RoadTracker(self.initial)  # the unpainted map's roads, copied at each reset

    # -- public state ---------------------------------------------------------------------------
    @property
    def grid(self) -> np.ndarray:
        """The current encoding matrix (a read-only view)."""
        p = self._pad
        view = self._padded[p : p + self.h, p : p + self.w]
        view.flags.writeable = False
        return view

    def garage(self) -> Garage:
        """The current matrix as a :class:`Garage`."""
        return Garage.painted(self.grid.copy(), self.initial.copy(), self.six_stall_axis, self.map_name,
                              self.entrance, self.exit)

    # -- gym API ---------------------------------------------------------------------------------
    def reset(self, *, seed: int | None = None, options: dict[str, Any] | None = None):
        super().reset(seed=seed)
        axis = (options or {}).get("six_stall_axis") or self.fixed_axis
        if axis is None:
            axis = AXES[int(self.np_random.integers(2))]
        if axis not in AXES:
            raise ValueError(f"six_stall_axis must be 'NS' or 'EW', got {axis!r}")
        self.six_stall_axis = axis
        self._padded = self._padded_initial.copy()
        self._padded.flags.writeable = True
        self._tracker = self._tracker0.copy()
        self.pos = self.entrance
        self.heading = self._inward
        self.errors = 0
        self.connected = False
        self.steps = 0
        self.stalls = 0
        self.free = self.free0
        self._utility = self._utility_values()
        return self._obs(), self._info()

    def step(self, action):
        reward, terminated, truncated = self._advance(action)
        return self._obs(), reward, terminated, truncated, self._info()

    def _advance(self, action) -> tuple[float, bool, bool]:
        """One step of ``action`` (0-3): the reward, terminated and truncated; no observation or info
        (:class:`~garage_mj.generation.vec_env.GarageGenVecEnv` builds those only where it needs them)."""
        a = int(action)
        if not 0 <= a < 4:
            raise ValueError(f"action must be 0-3 (west, east, north, south), got {action!r}")
        cfg = self.reward_config
        p = self._pad
        r, c = self.pos
        dr, dc = DELTAS[a]
        tr, tc = r + dr, c + dc
        padded = self._padded
        target = int(padded[tr + p, tc + p])  # off-grid reads OBSTACLE (padding)
        r_c = cfg.step_penalty
        terminated = False
        moved = False
        r_u = 0.0  # the utility changes only when a cell is painted
        if target == _OBST or target == _ENTRANCE:
            self.errors += 1
            r_c += cfg.collision_penalty
        elif target == _EXIT:
            moved = True
            self.connected = True
            terminated = True
            r_c += cfg.exit_bonus
        elif target == _ROAD:
            moved = True
        elif self._completes_square(tr + p, tc + p):
            self.errors += 1
            r_c += cfg.square_penalty
        else:
            moved = True
            self._paint(tr, tc, target)
            old = self._utility
            new = self._utility = self._utility_values()
            r_u = cfg.w_s * (new[0] - old[0]) + cfg.w_r * (new[1] - old[1]) + cfg.w_c * (new[2] - old[2])
        if moved:
            if a == OPPOSITE[self.heading]:
                r_c += cfg.backward_penalty
            self.heading = a
            self.pos = (tr, tc)
        if not terminated and self.errors > self.max_errors:
            terminated = True
            r_c += cfg.failure_penalty
        reward = cfg.k_c * r_c + cfg.k_u * r_u
        self.steps += 1
        truncated = not terminated and self.steps >= self.max_steps
        return float(reward), terminated, truncated

    def render(self):
        if self.render_mode == "ansi":
            return draw(self.grid, car=self.pos)
        if self.render_mode == "rgb_array":
            return grid_image(self.grid, car=self.pos, heading=self.heading)
        return None

    # -- internals -------------------------------------------------------------------------------
    def _completes_square(self, pr: int, pc: int) -> bool:
        padded = self._padded
        for dr in (-1, 1):
            if padded[pr + dr, pc] not in _ROAD_LIKE:
                continue
            for dc in (-1, 1):
                if padded[pr, pc + dc] in _ROAD_LIKE and padded[pr + dr, pc + dc] in _ROAD_LIKE:
                    return True
        return False

    def _paint(self, r: int, c: int, old: int) -> None:
        """Make (r, c) ROAD and recolour its FREE/stall neighbours by the stall rule."""
        p = self._pad
        padded = self._padded
        padded[r + p, c + p] = _ROAD
        self.stalls -= _STALLS[old]
        if old == _FREE:
            self.free -= 1
        self._tracker.add_road(r, c)
        axis = self.six_stall_axis
        for dr, dc in DELTAS:
            nr, nc = r + dr + p, c + dc + p
            v = int(padded[nr, nc])
            if v == _ROAD or v in _FIXED:
                continue  # also skips the padding, which reads OBSTACLE
            sides = 0
            obstacle = False
            for d, (er, ec) in enumerate(DELTAS):
                u = padded[nr + er, nc + ec]
                if u == _ROAD:
                    sides |= 1 << d
                elif u == _OBST and 0 <= nr + er - p < self.h and 0 <= nc + ec - p < self.w:
                    obstacle = True
            new = int(stall_code(sides, obstacle, axis))
            if new != v:
                padded[nr, nc] = new
                self.stalls += _STALLS[new] - _STALLS[v]
                self.free += (new == _FREE) - (v == _FREE)

    def _utility_values(self) -> tuple[float, float, float]:
        t = self._tracker
        return utility_values(self.stalls, self.free0, t.x_hist, t.y_hist, self.reward_config)

    def _coverage(self) -> float:
        return 1.0 - self.free / self.free0 if self.free0 else 0.0

    def _window(self) -> np.ndarray:
        """The k x k block codes around the car (off-grid cells read OBSTACLE)."""
        r, c = self.pos
        k = self.view_size
        r0, c0 = r + self._pad - k // 2, c + self._pad - k // 2
        return self._padded[r0 : r0 + k, c0 : c0 + k]

    def _fill_state(self, out: np.ndarray) -> None:
        """The 7 values after the window: error index, coverage, connected flag, one-hot heading."""
        out[0] = self.errors / self.max_errors if self.max_errors else float(self.errors > 0)
        out[1] = self._coverage()
        out[2] = float(self.connected)
        out[3:7] = 0.0
        out[3 + self.heading] = 1.0

    def _obs(self) -> np.ndarray:
        obs = np.empty(self._n_window + 7, dtype=np.float32)
        obs[: self._n_window] = self._eye[self._window()].reshape(-1)
        self._fill_state(obs[self._n_window :])
        return obs

    def _codes_obs(self, out: np.ndarray) -> None:
        """The observation with the window as k * k block codes instead of one-hot rows, into ``out``
        (k * k + 7 values): the one-hot observation is ``eye(NUM_CODES)[codes]`` and the same 7 values."""
        n = self.view_size * self.view_size
        out[:n] = self._window().reshape(-1)
        self._fill_state(out[n:])

    def codes_observation_space(self) -> spaces.Box:
        """The space of :meth:`_codes_obs`: k * k block codes (0 to NUM_CODES - 1), then the values that follow
        the one-hot window in :attr:`observation_space` (the 7 state values; a subclass's own after them)."""
        k2 = self.view_size * self.view_size
        n = self._n_window
        space = self.observation_space
        return spaces.Box(
            low=np.concatenate([np.zeros(k2, dtype=np.float32), space.low[n:]]),
            high=np.concatenate([np.full(k2, NUM_CODES - 1, dtype=np.float32), space.high[n:]]),
            dtype=np.float32,
        )

    def _info(self) -> dict[str, Any]:
        t = self._tracker
        ex, ey = t.mean_x(), t.mean_y()
        return {
            "errors": self.errors,
            "connected": self.connected,
            "coverage": self._coverage(),
            "usable": self.connected and self.errors <= self.max_errors,
            "stalls": self.stalls,
            "mean_road_length": ex,
            "mean_intersection_degree": ey,
            "difficulty": difficulty(ey, ex),
            "six_stall_axis": self.six_stall_axis,
        }
