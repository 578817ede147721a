"""What a driver costs per control step, on the same observations (target: learned <= 1.3x vision).

A cruise test's wall time depends on how long the driver keeps the car going: a driver that crashes
early finishes its tests sooner. This benchmark takes that out: it drives ``--tests`` tests of the
held-out m5 garages with the ``oracle`` (the paper's discrete actions) and, at every step, times
each driver's ``act`` on that same observation (interleaved, so the machine's load hits all alike),
and the env step itself. It prints, per driver, the median and mean ms per ``act`` and the cost of
a control step with that driver (env step + act) relative to ``vision``.

Then, per simulated second of cruise (``--cruise-garages``, 0: skip): each driver drives the same
cruise tests (2 per garage, :func:`~garage_mj.driving.cruise.run_test`, discrete actions, seed 0) in
this one process, once to warm up (imports, scenes) and then ``--rounds`` times, interleaved; the wall
time per simulated second of each driver, relative to ``vision``. A driver that crashes early ends its
tests sooner, so this is per simulated second, not per test.

    MUJOCO_GL=egl .venv/bin/python eval/bench_driver_step.py --tests 8 --json docs/learned_driver/driver_step.json
"""

from __future__ import annotations

import argparse
import json
import os
import time
from pathlib import Path

import numpy as np
from _provenance import provenance  # eval/_provenance.py: command, date, machine, commit

from garage_mj.driving.drivers import load_driver
from garage_mj.driving.garage_set import GarageSet
from garage_mj.driving.sim.drive_env import GarageDriveEnv

ROOT = Path(__file__).resolve().parents[1]
HELD_OUT = ROOT / "docs" / "learned_driver" / "heldout" / "m5_unseen_seed.json"


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--tests", type=int, default=8, help="tests, one per garage of the held-out m5 set (default 8)")
    p.add_argument("--drivers", default="vision,learned,waypoint", help="drivers to time (default vision,learned,waypoint)")
    p.add_argument("--cruise-garages", type=int, default=6, help="held-out m5 garages of the cruise part, 2 tests each (default 6; 0: skip)")
    p.add_argument("--rounds", type=int, default=2, help="timed rounds of the cruise part (default 2)")
    p.add_argument("--json", type=Path, help="write the figures here")
    args = p.parse_args(argv)
    prov = provenance(argv)  # before the run: the load it starts at
    names = args.drivers.split(",")
    drivers = {n: load_driver(n) for n in names}
    garages = list(GarageSet.from_json(HELD_OUT))[: args.tests]
    oracle = load_driver("oracle")
    acts: dict[str, list[float]] = {n: [] for n in names}
    env_steps: list[float] = []
    for k, src in enumerate(garages):
        env = GarageDriveEnv(garage=src.garage, action_type="discrete")
        obs, _ = env.reset(seed=k)
        info = env.driver_info(k)
        oracle.reset(info)
        for d in drivers.values():
            d.reset(info)
        while True:
            for n, d in drivers.items():
                t0 = time.perf_counter()
                d.act(obs)
                acts[n].append(time.perf_counter() - t0)
            action = oracle.act(obs)
            t0 = time.perf_counter()
            obs, _, term, trunc, _ = env.step(action)
            env_steps.append(time.perf_counter() - t0)
            if term or trunc:
                break
        env.close()
    step = float(np.mean(env_steps))
    base = step + float(np.mean(acts["vision"])) if "vision" in acts else None
    out = {"tests": len(garages), "steps": len(env_steps), "env_step_ms": round(1e3 * step, 3),
           "load_average": [round(x, 2) for x in os.getloadavg()], "drivers": {}}
    print(f"{len(garages)} tests, {len(env_steps)} steps; env step {1e3 * step:.3f} ms mean")
    for n, t in acts.items():
        a = np.array(t)
        row = {"act_ms_median": round(1e3 * float(np.median(a)), 3), "act_ms_mean": round(1e3 * float(a.mean()), 3),
               "step_with_driver_ms": round(1e3 * (step + float(a.mean())), 3)}
        if base:
            row["cost_vs_vision"] = round((step + float(a.mean())) / base, 3)
        out["drivers"][n] = row
        print(f"{n:10s} act {row['act_ms_median']:.3f} ms median, {row['act_ms_mean']:.3f} mean; "
              f"step with it {row['step_with_driver_ms']:.3f} ms" +
              (f" = {row['cost_vs_vision']:.2f}x vision's" if base else ""))
    if args.cruise_garages > 0:
        out["cruise"] = cruise_cost(names, list(GarageSet.from_json(HELD_OUT))[: args.cruise_garages], args.rounds)
    if args.json:
        args.json.parent.mkdir(parents=True, exist_ok=True)
        args.json.write_text(json.dumps({**out, "provenance": prov}, indent=1) + "\n")
    return 0


def cruise_cost(names: list[str], garages: list, rounds: int) -> dict:
    """Wall s per simulated s of cruise tests, per driver, interleaved in this process (module docstring)."""
    from garage_mj.driving.cruise import run_test
    from garage_mj.driving.sources import CruiseSettings

    def drive(name: str) -> tuple[float, float]:
        settings = CruiseSettings(driver=name, seed=0, action_type="discrete")
        t0, sim = time.perf_counter(), 0.0
        for src in garages:
            for index in range(2):
                sim += float(run_test(src, index, settings)["time"])
        return time.perf_counter() - t0, sim

    for n in names:  # warm up: torch, the model, the scenes
        drive(n)
    wall = {n: 0.0 for n in names}
    sim = dict(wall)
    for _ in range(rounds):
        for n in names:
            w, t = drive(n)
            wall[n] += w
            sim[n] += t
    out = {"garages": len(garages), "tests_per_driver": 2 * len(garages), "rounds": rounds, "drivers": {}}
    base = wall["vision"] / sim["vision"] if "vision" in wall else None
    print(f"cruise, one process, {2 * len(garages)} tests per driver x {rounds} rounds:")
    for n in names:
        ms = 1e3 * wall[n] / sim[n]
        row = {"wall_s": round(wall[n], 2), "sim_s": round(sim[n], 1), "ms_per_sim_s": round(ms, 2)}
        if base:
            row["cost_vs_vision"] = round(wall[n] / sim[n] / base, 3)
        out["drivers"][n] = row
        print(f"{n:10s} {ms:.2f} ms per simulated s ({sim[n]:.0f} simulated s)" +
              (f" = {row['cost_vs_vision']:.2f}x vision's" if base else ""))
    return out


if __name__ == "__main__":
    raise SystemExit(main())
