"""Benchmark: cruise tests with the camera on, and the projected wall time of the paper experiment.

    python eval/bench_cruise.py [--map m5_13x13_aligned] [--tests 10] [--workers 2] [--driver vision]
        [--pedestrians 2 --moving-cars 1 --clutter 2]     # with actors

Runs ``--tests`` seeded tests of ``garage_mj/GarageDrive-v0`` (built-in ``--driver`` with the action
type it declares, depth + segmentation 64x64 at 10 Hz) in ``--workers`` processes, one env per worker, and prints seconds
per test, simulated seconds per wall second, camera frames per second (render only, and
depth+segmentation on their own over the recorded states) and the projected wall time of the
paper experiment (target: 2,500 tests in <= 30 minutes on 2 cores). Env build time is reported
apart: the experiment builds one env per garage per worker, not per test.
"""

from __future__ import annotations

import argparse
import multiprocessing as mp
import time

import gymnasium as gym

import garage_mj  # noqa: F401  (MUJOCO_GL, registers the envs)
from garage_mj.driving.drivers import action_type_of, load_driver
from garage_mj.grid.painters import paint_garage

PAPER_TESTS = 2500  # 50 garages x 50 tests (docs/spec.md section 5)
TARGET_MIN = 30.0  # [min] target on 2 cores
_ENV = {}  # per worker process: the env, built once


def _env(map_name: str, seed: int, action_type: str, scenario: dict | None = None):
    if "env" not in _ENV:
        t0 = time.perf_counter()
        _ENV["env"] = gym.make("garage_mj/GarageDrive-v0", garage=paint_garage(map_name, seed=seed),
                               action_type=action_type, scenario=scenario)
        _ENV["build_s"] = time.perf_counter() - t0
    return _ENV["env"]


def run_one(job: tuple[str, int, str, int]) -> dict:
    """One cruise test; wall time, simulated time and camera time."""
    map_name, garage_seed, driver_name, seed, scenario = job
    env = _env(map_name, garage_seed, action_type_of(driver_name), scenario)
    base = env.unwrapped
    camera = base.camera
    render, spent = camera.render, [0.0, 0]

    def timed(data):
        t = time.perf_counter()
        out = render(data)
        spent[0] += time.perf_counter() - t
        spent[1] += 1
        return out

    camera.render = timed
    driver = load_driver(driver_name)
    t0 = time.perf_counter()
    obs, _ = env.reset(seed=seed)
    driver.reset(base.driver_info(seed))
    info = {}
    done = False
    while not done:
        obs, _, term, trunc, info = env.step(driver.act(obs))
        done = term or trunc
    wall = time.perf_counter() - t0
    camera.render = render
    return {"wall": wall, "sim": float(base.data.time), "render": spent[0], "frames": spent[1],
            "outcome": info.get("outcome", "?"), "build": _ENV.pop("build_s", 0.0)}


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--map", default="m5_13x13_aligned")
    ap.add_argument("--garage-seed", type=int, default=1)
    ap.add_argument("--tests", type=int, default=10)
    ap.add_argument("--workers", type=int, default=2)
    ap.add_argument("--driver", default="vision")
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--pedestrians", type=int, default=0)
    ap.add_argument("--moving-cars", type=int, default=0)
    ap.add_argument("--clutter", type=int, default=0)
    args = ap.parse_args()
    scenario = {"pedestrians": args.pedestrians, "moving_cars": args.moving_cars, "clutter": args.clutter}
    jobs = [(args.map, args.garage_seed, args.driver, args.seed + i, scenario) for i in range(args.tests)]
    t0 = time.perf_counter()
    if args.workers > 1:
        with mp.get_context("spawn").Pool(args.workers) as pool:
            rows = pool.map(run_one, jobs, chunksize=1)
    else:
        rows = [run_one(j) for j in jobs]
    total = time.perf_counter() - t0
    builds = [r["build"] for r in rows if r["build"]]
    wall = sum(r["wall"] for r in rows)
    sim = sum(r["sim"] for r in rows)
    render = sum(r["render"] for r in rows)
    frames = sum(r["frames"] for r in rows)
    outcomes = {o: sum(r["outcome"] == o for r in rows) for o in sorted({r["outcome"] for r in rows})}
    per_test = (total - max(builds, default=0.0)) / len(rows) * args.workers  # [s] one worker's wall per test
    projected = PAPER_TESTS * per_test / args.workers / 60  # [min]
    print(f"{args.map} (garage seed {args.garage_seed}), driver {args.driver} ({action_type_of(args.driver)} "
          f"actions, its own), actors {scenario}, {len(rows)} tests, "
          f"{args.workers} workers; outcomes {outcomes}")
    print(f"{'env build (per worker)':38s} {sum(builds) / max(len(builds), 1):9.2f} s")
    print(f"{'seconds per test (one worker)':38s} {per_test:9.2f} s   (in-test mean {wall / len(rows):.2f} s)")
    print(f"{'simulated s per wall s (per worker)':38s} {sim / wall:9.1f}     (mean test {sim / len(rows):.1f} s sim)")
    print(f"{'camera frames/s (depth+seg 64x64)':38s} {frames / render:9.0f}     "
          f"(camera {100 * render / wall:.0f}% of test time)")
    print(f"{'projected paper experiment':38s} {projected:9.1f} min for {PAPER_TESTS} tests on {args.workers} "
          f"workers (target <= {TARGET_MIN:.0f}; + env builds: 50 garages x {sum(builds) / max(len(builds), 1):.1f} s "
          f"/ {args.workers} = {50 * sum(builds) / max(len(builds), 1) / args.workers / 60:.1f} min)")


if __name__ == "__main__":
    main()
