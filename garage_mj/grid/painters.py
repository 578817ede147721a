"""Scripted painters: seeded policies for GarageGenEnv that need no training.

Used by tests, benchmarks and the demo to make painted garages quickly. ``ExitSeekingPainter``
mixes random moves with steps along a shortest path to the exit, so it reaches the exit
(a usable garage) on every shipped map while still painting varied roads.
"""

from __future__ import annotations

from collections import deque

import gymnasium as gym
import numpy as np

from garage_mj.core.geometry import DELTAS
from garage_mj.grid.blocks import Axis, Block
from garage_mj.grid.garage import Garage


class ExitSeekingPainter:
    """With probability ``greed`` step towards the exit (BFS over non-obstacle cells), else randomly."""

    def __init__(self, greed: float = 0.5, seed: int | None = None) -> None:
        self.greed = greed
        self.rng = np.random.default_rng(seed)

    def act(self, env) -> int:
        env = env.unwrapped
        if self.rng.random() >= self.greed:
            return int(self.rng.integers(4))
        step = _first_step(env.grid, env.pos, env.exit)
        return int(self.rng.integers(4)) if step is None else step


def _first_step(grid: np.ndarray, start: tuple[int, int], goal: tuple[int, int]) -> int | None:
    h, w = grid.shape
    first: dict[tuple[int, int], int] = {start: -1}
    queue = deque([start])
    while queue:
        r, c = queue.popleft()
        if (r, c) == goal:
            return first[(r, c)]
        for d, (dr, dc) in enumerate(DELTAS):
            q = (r + dr, c + dc)
            if 0 <= q[0] < h and 0 <= q[1] < w and q not in first:
                if grid[q] in (Block.OBSTACLE, Block.ENTRANCE):
                    continue
                first[q] = d if first[(r, c)] < 0 else first[(r, c)]
                queue.append(q)
    return None


def paint_garage(
    map: str | Garage = "tiny_7x11",
    seed: int = 0,
    greed: float = 0.5,
    six_stall_axis: Axis | None = None,
    usable: bool = True,
    max_episodes: int = 200,
) -> Garage:
    """Paint one garage with :class:`ExitSeekingPainter` (the first usable one if ``usable``)."""
    env = gym.make("garage_mj/GarageGen-v0", map=map, six_stall_axis=six_stall_axis)
    painter = ExitSeekingPainter(greed, seed)
    for episode in range(max_episodes):
        env.reset(seed=seed * 100_003 + episode)
        done = False
        info: dict = {}
        while not done:
            _, _, term, trunc, info = env.step(painter.act(env))
            done = term or trunc
        if info["usable"] or not usable:
            return env.unwrapped.garage()
    raise RuntimeError(f"no usable garage on {map!r} in {max_episodes} episodes (seed {seed})")
