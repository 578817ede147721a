"""Where a park test's wall time goes with the learned parking driver: reset, cameras, physics, the driver.

    MUJOCO_GL=egl .venv/bin/python eval/bench_park_step.py [--driver learned:park] [--set m5_unseen_seed]
        [--garages 4] [--tests 4] [--geometries default parallel] [--scenario none] [--json OUT.json]

Drives ``--tests`` park tests on each of the first ``--garages`` garages of a held-out set
(``docs/learned_driver/heldout/``) in each geometry, in this one process (no worker pool: what one worker does), the
driver built once before the clock starts, as :func:`garage_mj.driving.cruise.run_test` runs a test: ``reset`` (the
test drawn, its parked cars placed, the reference park plan, the first observation), then ``driver.act`` and
``env.step`` until the test ends. Each control step (0.1 s simulated) is split into the two cameras' renders (depth
and segmentation, timed around each camera's ``render``), the rest of ``env.step`` (physics substeps, contacts, the
ultrasonic rays, the outcome monitor, the observation's other parts) and the driver's ``act``. Prints and writes
(``--json``) the simulated seconds per wall second, the time per part and what each part alone would allow: the
ceiling is the simulated time over the time of the parts that no driver or env change can skip (the two renders and
the physics of the step), an upper bound for this machine.
"""

from __future__ import annotations

import argparse
import json
import statistics
import time
from pathlib import Path

from _provenance import provenance  # eval/_provenance.py: command, date, machine, commit

from garage_mj.core.fsutil import write_json
from garage_mj.driving.drivers import action_type_of, load_driver
from garage_mj.driving.episode import cached_env, close_cached_env
from garage_mj.driving.garage_set import load_garage_set
from garage_mj.driving.park_geometries import PARK_GEOMETRIES
from garage_mj.driving.sim.outcomes import NOT_DRIVEN
from garage_mj.driving.sources import CruiseSettings, cruise_seed

ROOT = Path(__file__).resolve().parents[1]
HELDOUT = ROOT / "docs" / "learned_driver" / "heldout"


class _Timed:
    """Wraps a camera's ``render`` on the instance and adds up its wall time."""

    def __init__(self, camera) -> None:
        self.seconds, self.calls = 0.0, 0
        self._render = camera.render
        camera.render = self

    def __call__(self, data):
        t = time.perf_counter()
        out = self._render(data)
        self.seconds += time.perf_counter() - t
        self.calls += 1
        return out


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--driver", default="learned:park")
    ap.add_argument("--set", default="m5_unseen_seed", help="held-out garage set (docs/learned_driver/heldout/)")
    ap.add_argument("--garages", type=int, default=4)
    ap.add_argument("--tests", type=int, default=4)
    ap.add_argument("--geometries", nargs="*", default=["default", "parallel"], choices=sorted(PARK_GEOMETRIES))
    ap.add_argument("--scenario", default="none", help="actor scenario (none: no actors)")
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--json", type=Path)
    args = ap.parse_args(argv)
    prov = provenance(argv)
    sources = list(load_garage_set(str(HELDOUT / f"{args.set}.json")))[: args.garages]
    driver = load_driver(args.driver)  # built before the clock, as a run builds it once per process
    action_type = action_type_of(args.driver)
    reset_s = act_s = step_s = sim_s = render_s = 0.0
    frames = steps = tests = 0
    per_test = []
    for geometry in args.geometries:
        env_kwargs = PARK_GEOMETRIES[geometry].env_kwargs()
        if args.scenario != "none":
            env_kwargs["scenario"] = args.scenario
        settings = CruiseSettings(driver=args.driver, seed=args.seed, task="park", maneuver="any",
                                  env=env_kwargs).resolved(action_type)  # the sensors the driver declares on
        for source in sources:
            env = cached_env(source, settings)  # the env a run's worker builds for these settings
            cams = [_Timed(c) for c in (env.camera, env.rear_camera) if c is not None]
            try:
                for index in range(args.tests):
                    seed = cruise_seed(args.seed, source.hash, index)
                    t0 = time.perf_counter()
                    obs, info = env.reset(seed=seed)
                    t1 = time.perf_counter()
                    if info.get("outcome") in NOT_DRIVEN:  # never driven: left out, as the park benchmarks do
                        continue
                    reset_s += t1 - t0
                    before = sum(c.seconds for c in cams), sum(c.calls for c in cams)
                    driver.reset(env.driver_info(seed))
                    n, a_s, s_s = 0, 0.0, 0.0
                    while True:
                        ta = time.perf_counter()
                        action = driver.act(obs)
                        tb = time.perf_counter()
                        obs, _, term, trunc, info = env.step(action)
                        tc = time.perf_counter()
                        a_s += tb - ta
                        s_s += tc - tb
                        n += 1
                        if term or trunc:
                            break
                    act_s += a_s
                    step_s += s_s
                    steps += n
                    tests += 1
                    sim_s += info["time"]
                    per_test.append(info["time"] / (t1 - t0 + a_s + s_s))
                    # the drive's renders (the reset's first observation is the reset's)
                    render_s += sum(c.seconds for c in cams) - before[0]
                    frames += sum(c.calls for c in cams) - before[1]
            finally:
                close_cached_env()
    wall = reset_s + act_s + step_s
    physics_etc = step_s - render_s
    ms = 1000.0 / steps
    out = {
        "driver": args.driver, "set": args.set, "garages": len(sources), "tests_per_garage": args.tests,
        "geometries": args.geometries, "scenario": args.scenario, "tests": tests, "control_steps": steps,
        "simulated_s": round(sim_s, 1), "wall_s": round(wall, 2),
        "sim_s_per_wall_s": round(sim_s / wall, 1),
        "sim_s_per_wall_s_median_test": round(statistics.median(per_test), 1),
        "camera_frames": frames, "per_control_step_ms": {"cameras": round(render_s * ms, 3), "env_step_without_cameras":
                                round(physics_etc * ms, 3), "driver_act": round(act_s * ms, 3),
                                "reset_spread": round(reset_s * ms, 3)},
        "reset_ms_per_test": round(1000 * reset_s / max(tests, 1), 1),
        "share": {"reset": round(reset_s / wall, 3), "cameras": round(render_s / wall, 3),
                  "env_step_without_cameras": round(physics_etc / wall, 3), "driver_act": round(act_s / wall, 3)},
        # what the drive would run at with only the cameras and the rest of the env step (no driver, no reset)
        "ceiling_env_only_sim_s_per_wall_s": round(sim_s / step_s, 1),
        "ceiling_cameras_only_sim_s_per_wall_s": round(sim_s / render_s, 1) if render_s else None,
        "provenance": prov,
    }
    print(json.dumps({k: v for k, v in out.items() if k != "provenance"}, indent=1))
    if args.json:
        args.json.parent.mkdir(parents=True, exist_ok=True)
        write_json(args.json, out, indent=1)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
