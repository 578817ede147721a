"""Benchmark: a parking car's sensors: the front and rear cameras together, and what the rangefinders cost.

    .venv/bin/python eval/bench_park_sensors.py [--map m5_13x13_aligned] [--garage-seed 1] [--tests 6]
        [--task park] [--rounds 3] [--size 64] [--core 0] [--json docs/bench_park_sensors.json]

Builds ``GarageDrive-v0`` on one painted garage with the rear camera and the ultrasonic sensors on
(``sensors="rear_camera,ultrasonic"``; depth + segmentation, ``--size`` pixels square, as the front camera) and
drives ``--tests`` seeded tests of ``--task`` with the ``oracle`` (park tests reverse into their stalls, so the rear
camera looks at parked cars and walls), recording the car's pose at every control step. Pinned to one core
(``--core``; ``LP_NUM_THREADS=0``, the sensors module's default, draws each frame in this thread) it then renders,
on the recorded poses, in ``--rounds`` interleaved rounds:

- the front camera alone, the rear camera alone (frames/s);
- both, front then rear per pose: frame pairs/s (the target: >= 2,500 at 64 x 64);

each per wall second and per CPU second of the rendering thread (on a machine other jobs keep busy, the second
is what one core of its own would give: the wall figure also counts the time the thread waited for the core);

then the ultrasonic readings (``Ultrasonic.read``: 12 rays cast per observation, as the env does) per second, and
replays the recorded controls through ``mj_step`` in the env's scene and in the same scene with the car's 12
MuJoCo rangefinder sensors kept (``attach_car(..., ultrasonic=True)``: MuJoCo casts their rays at every physics
step), steps/s: what the env saves by casting them once per observation. Medians over the rounds; the load
average is recorded beside them (other jobs on the machine slow every figure).
"""

from __future__ import annotations

import argparse
import functools
import json
import os
import statistics
import time
from pathlib import Path

from _provenance import provenance  # eval/_provenance.py: command, date, machine, commit


def _record(env, driver, tests: int):
    """Drive ``tests`` seeded tests; per test its seed, controls and poses (one per control step)."""
    base = env.unwrapped
    runs, outcomes = [], []
    for seed in range(tests):
        obs, _ = env.reset(seed=seed)
        driver.reset(base.driver_info(seed))
        ctrls, poses, done, info = [], [base.data.qpos.copy()], False, {}
        while not done:
            obs, _, term, trunc, info = env.step(driver.act(obs))
            ctrls.append(base.data.ctrl.copy())
            poses.append(base.data.qpos.copy())
            done = term or trunc
        outcomes.append(info.get("outcome", "?"))
        runs.append((seed, ctrls, poses))
    return runs, outcomes


def _frames(env, runs, cameras) -> tuple[float, float]:
    """Frames (or frame pairs, ...) of ``cameras`` rendered one after the other on every recorded pose, per wall
    second and per CPU second of this thread (which draws them: ``LP_NUM_THREADS=0``)."""
    import mujoco

    base = env.unwrapped
    model, data = base.model, base.data
    n, spent, cpu = 0, 0.0, 0.0
    for seed, _, poses in runs:
        env.reset(seed=seed)  # the test's parked cars
        for q in poses:
            data.qpos[:] = q
            mujoco.mj_kinematics(model, data)
            mujoco.mj_camlight(model, data)
            t, c = time.perf_counter(), time.thread_time()
            for cam in cameras:
                cam.render(data)
            spent += time.perf_counter() - t
            cpu += time.thread_time() - c
            n += 1
    return n / spent, n / cpu


def _sonar(env, runs) -> float:
    """Ultrasonic readings per second on every recorded pose."""
    import mujoco

    base = env.unwrapped
    model, data, sonar = base.model, base.data, base.ultrasonic
    n, spent = 0, 0.0
    for seed, _, poses in runs:
        env.reset(seed=seed)
        for q in poses:
            data.qpos[:] = q
            mujoco.mj_kinematics(model, data)
            t = time.perf_counter()
            sonar.read(data)
            spent += time.perf_counter() - t
            n += 1
    return n / spent


def _physics(env, runs) -> float:
    """Physics steps per second replaying the recorded controls (the same substeps, the same parked cars)."""
    import mujoco

    base = env.unwrapped
    model, data = base.model, base.data
    steps, spent = 0, 0.0
    for seed, ctrls, _ in runs:
        env.reset(seed=seed)
        t = time.perf_counter()
        for c in ctrls:
            data.ctrl[:] = c
            for _ in range(base.n_substeps):
                mujoco.mj_step(model, data)
        spent += time.perf_counter() - t
        steps += len(ctrls) * base.n_substeps
    return steps / spent


def main() -> None:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("--map", default="m5_13x13_aligned")
    p.add_argument("--garage-seed", type=int, default=1)
    p.add_argument("--tests", type=int, default=6)
    p.add_argument("--task", choices=("park", "avp", "cruise"), default="park")
    p.add_argument("--rounds", type=int, default=3)
    p.add_argument("--size", type=int, default=64, help="camera image side [px]")
    p.add_argument("--core", type=int, default=0, help="the CPU core to pin to (-1: no pinning)")
    p.add_argument("--json", type=Path, help="also write the results here")
    args = p.parse_args()
    if args.core >= 0 and hasattr(os, "sched_setaffinity"):
        os.sched_setaffinity(0, {args.core})

    import gymnasium as gym

    import garage_mj  # noqa: F401 - registers the env
    from garage_mj.driving.drivers import load_driver
    from garage_mj.driving.sim import drive_env
    from garage_mj.grid.painters import paint_garage

    garage = paint_garage(args.map, seed=args.garage_seed)
    camera = {"width": args.size, "height": args.size}
    kw = dict(garage=garage, action_type="continuous", task=args.task, camera=camera)
    env = gym.make("garage_mj/GarageDrive-v0", sensors="rear_camera,ultrasonic", **kw)
    attach = drive_env.attach_car  # the same scene with the car's MuJoCo rangefinder sensors kept
    drive_env.attach_car = functools.partial(attach, ultrasonic=True)
    try:
        sensored = gym.make("garage_mj/GarageDrive-v0", **kw)
    finally:
        drive_env.attach_car = attach
    assert sensored.unwrapped.model.nsensor == env.unwrapped.model.nsensor + 12
    runs, outcomes = _record(env, load_driver("oracle"), args.tests)
    base = env.unwrapped
    front, rear = base.camera, base.rear_camera
    rows = {"front": [], "rear": [], "pairs": [], "front_cpu": [], "rear_cpu": [], "pairs_cpu": [], "ultrasonic": [],
            "physics_env": [], "physics_rangefinders": []}
    loads = [os.getloadavg()[0]]
    for _ in range(args.rounds):
        for name, cams in (("pairs", (front, rear)), ("front", (front,)), ("rear", (rear,))):
            wall, cpu = _frames(env, runs, cams)
            rows[name].append(wall)
            rows[f"{name}_cpu"].append(cpu)
        rows["ultrasonic"].append(_sonar(env, runs))
        rows["physics_env"].append(_physics(env, runs))
        rows["physics_rangefinders"].append(_physics(sensored, runs))
        loads.append(os.getloadavg()[0])
    med = {k: statistics.median(v) for k, v in rows.items()}
    out = {
        "map": args.map, "garage_seed": args.garage_seed, "task": args.task, "tests": args.tests,
        "outcomes": outcomes, "poses": sum(len(r[2]) for r in runs), "size": args.size, "rounds": args.rounds,
        "core": args.core, "gl": os.environ.get("MUJOCO_GL", "egl"),
        "front_frames_per_s": round(med["front"]), "rear_frames_per_s": round(med["rear"]),
        "pairs_per_s": round(med["pairs"]), "pairs_target": 2500, "pairs_met": med["pairs"] >= 2500,
        "front_frames_per_cpu_s": round(med["front_cpu"]), "rear_frames_per_cpu_s": round(med["rear_cpu"]),
        "pairs_per_cpu_s": round(med["pairs_cpu"]), "pairs_met_per_cpu_s": med["pairs_cpu"] >= 2500,
        "ultrasonic_reads_per_s": round(med["ultrasonic"]),
        "physics_steps_per_s": round(med["physics_env"]),
        "physics_steps_per_s_with_rangefinder_sensors": round(med["physics_rangefinders"]),
        "rangefinder_sensors_cost_pct": round(100 * (med["physics_env"] / med["physics_rangefinders"] - 1), 1),
        "substeps": env.unwrapped.n_substeps,
        "per_round": {k: [round(v) for v in vs] for k, vs in rows.items()},
        "load": [round(v, 2) for v in loads], "provenance": provenance(),
    }
    env.close()
    sensored.close()
    text = json.dumps(out, indent=2)
    print(text)
    if args.json:
        args.json.write_text(text + "\n")


if __name__ == "__main__":
    main()
