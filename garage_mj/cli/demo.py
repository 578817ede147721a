"""``garage-mj demo``: the main job on a small garage, end to end with what exists."""

from __future__ import annotations

import argparse

import gymnasium as gym
import numpy as np

from garage_mj.metrics import evaluate
from garage_mj.textdraw import draw


def register(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser(
        "demo",
        help="run the main job on a small garage",
        description="Random-policy generation on a map: prints each episode's metrics and "
        "draws the best usable garage (highest return) as text.",
    )
    p.add_argument("--map", default="tiny_7x11", help="shipped map name or map file (default: tiny_7x11)")
    p.add_argument("--episodes", type=int, default=20, help="episodes to run (default: 20)")
    p.add_argument("--seed", type=int, default=0, help="random seed (default: 0)")
    p.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    env = gym.make("garage_mj/GarageGen-v0", map=args.map)
    rng = np.random.default_rng(args.seed)
    best = None
    print(f"random-policy generation on {args.map}, {args.episodes} episodes, seed {args.seed}")
    for ep in range(args.episodes):
        obs, info = env.reset(seed=args.seed + ep)
        ret, done = 0.0, False
        while not done:
            obs, r, term, trunc, info = env.step(int(rng.integers(4)))
            ret += r
            done = term or trunc
        g = env.unwrapped.garage()
        m = evaluate(g)
        print(
            f"episode {ep:3d}  return {ret:8.1f}  usable {str(m.usable):5}  coverage {m.coverage:.2f}  "
            f"difficulty {m.difficulty:.3f}  stalls {m.stalls:3d}  E[X] {m.mean_road_length:.2f}  "
            f"E[Y] {m.mean_intersection_degree:.2f}  errors {info['errors']}"
        )
        if info["usable"] and (best is None or ret > best[0]):
            best = (ret, ep, g, m)
    env.close()
    if best is None:
        print("no usable garage this time; try more --episodes")
        return 0
    ret, ep, g, m = best
    print(f"\nbest usable garage: episode {ep}, return {ret:.1f}, stalls {m.stalls}, axis {g.six_stall_axis}")
    print(draw(g.grid, legend=True))
    return 0
