"""Benchmark: random-policy GarageGenEnv steps per second, single process.

    python eval/bench_env.py [--map m5_13x13_aligned] [--steps 200000] [--seed 0]

Reports both the raw env (``env.unwrapped``) and the ``gym.make`` env with its default
wrappers (what SB3 sees). Target: >= 20,000 steps/s on m5_13x13_aligned.
"""

from __future__ import annotations

import argparse
import time

import gymnasium as gym
import numpy as np

import garage_mj  # noqa: F401  (registers the env)


def run(env, steps: int, seed: int) -> float:
    rng = np.random.default_rng(seed)
    actions = rng.integers(4, size=steps)
    env.reset(seed=seed)
    t0 = time.perf_counter()
    for a in actions:
        _, _, term, trunc, _ = env.step(a)
        if term or trunc:
            env.reset()
    return steps / (time.perf_counter() - t0)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--map", default="m5_13x13_aligned")
    ap.add_argument("--steps", type=int, default=200_000)
    ap.add_argument("--seed", type=int, default=0)
    args = ap.parse_args()
    wrapped = gym.make("garage_mj/GarageGen-v0", map=args.map)
    raw = run(wrapped.unwrapped, args.steps, args.seed)
    made = run(wrapped, args.steps, args.seed)
    print(f"map {args.map}, {args.steps} random steps")
    print(f"raw env:       {raw:10,.0f} steps/s")
    print(f"gym.make env:  {made:10,.0f} steps/s")


if __name__ == "__main__":
    main()
