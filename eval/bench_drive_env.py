"""Benchmark: the drive env against its own ceiling (physics alone + camera alone), workers, before/after.

    .venv/bin/python eval/bench_drive_env.py [--map m5_13x13_aligned] [--garage-seed 1] [--tests 10]
        [--rounds 3] [--workers 1 2] [--baseline-tree /tmp/before_speed] [--json docs/bench_drive_env.json]

Each measurement runs in a fresh process (``--probe``) that builds ``garage_mj/GarageDrive-v0`` on one
painted garage (camera on: depth + segmentation 64x64 at 10 Hz, continuous actions) and drives
``--tests`` seeded tests with the ``vision`` driver, recording each control step's controls and pose.
On the same scene and the same tests it then prints:

- full env: simulated s per wall s of the whole loop (``env.step`` and the driver), and without the
  driver's own compute (``driver.act`` timed apart);
- physics only: the recorded controls replayed through an ``mj_step`` loop (the same substeps, the
  same parked cars), steps/s and the simulated s per wall s they make;
- camera only: ``env.camera.render`` on the recorded poses, frames/s and the simulated s per wall s
  at the env's control rate (one frame per control period);
- the ceiling: physics and camera one after the other in one process, 1 / (1/physics + 1/camera),
  and how far the full env is below it (ceiling / full). Each test is driven, then replayed for
  physics alone and for the camera alone, so the three figures are taken under the same load;
  the full loop is also given per CPU second of the process (less sensitive to other jobs).

``--workers 1 2``: as many probe processes at once (each its own env, started together after all
have built their scene); their summed simulated seconds over the longest wall time, and each
worker's simulated seconds per CPU second of its own (against one worker's: below 1 the workers
slow each other down; near 1 with poor scaling the machine had no free core to give). With
``--baseline-tree DIR`` every round also runs the same probe on another checkout of the code
(``PYTHONPATH=DIR``; e.g. ``git worktree add /tmp/before_speed <commit>``), interleaved with this
tree's, so the before/after ratio is taken under the same load; medians over ``--rounds``. Probes get
the caller's environment, so each tree applies its own defaults (e.g. ``LP_NUM_THREADS``). The load
average is recorded next to each figure: other jobs on the machine slow both trees alike, not equally.
"""

from __future__ import annotations

import argparse
import json
import os
import statistics
import subprocess
import sys
import time
from pathlib import Path

from _provenance import provenance  # eval/_provenance.py: command, date, machine, commit

HERE = Path(__file__).resolve().parent.parent  # this tree


def probe(map_name: str, garage_seed: int, tests: int, wait: bool) -> dict:
    """One process's measurements on the code it imports (see the module docstring)."""
    import gymnasium as gym
    import mujoco

    import garage_mj
    from garage_mj.driving.drivers import load_driver
    from garage_mj.grid.painters import paint_garage

    t0 = time.perf_counter()
    env = gym.make("garage_mj/GarageDrive-v0", garage=paint_garage(map_name, seed=garage_seed),
                   action_type="continuous")
    base = env.unwrapped
    model, data, camera = base.model, base.data, base.camera
    driver = load_driver("vision")
    build = time.perf_counter() - t0
    if wait:  # start together with the other workers
        print("ready", flush=True)
        sys.stdin.readline()
    load = os.getloadavg()[0]
    sim = driving = wall = cpu = phys = cam = 0.0
    steps = frames = 0
    outcomes = []
    for seed in range(tests):  # per test: drive it, then physics alone and camera alone on it (same load)
        t0, c0 = time.perf_counter(), time.process_time()
        obs, _ = env.reset(seed=seed)
        driver.reset(base.driver_info(seed))
        ctrls, poses, info, done = [], [], {}, False
        while not done:
            t = time.perf_counter()
            action = driver.act(obs)
            driving += time.perf_counter() - t
            obs, _, term, trunc, info = env.step(action)
            ctrls.append(data.ctrl.copy())
            poses.append(data.qpos.copy())
            done = term or trunc
        wall += time.perf_counter() - t0
        cpu += time.process_time() - c0
        sim += float(data.time)
        outcomes.append(info.get("outcome", "?"))
        if wait:
            continue
        env.reset(seed=seed)  # physics only: the same controls through mj_step, the same parked cars
        t = time.perf_counter()
        for c in ctrls:
            data.ctrl[:] = c
            for _ in range(base.n_substeps):
                mujoco.mj_step(model, data)
        phys += time.perf_counter() - t
        steps += len(ctrls) * base.n_substeps
        env.reset(seed=seed)  # camera only: the recorded poses, one frame each
        for q in poses:
            data.qpos[:] = q
            mujoco.mj_kinematics(model, data)
            mujoco.mj_camlight(model, data)
            t = time.perf_counter()
            camera.render(data)
            cam += time.perf_counter() - t
            frames += 1
    out = {"tree": str(Path(garage_mj.__file__).resolve().parent.parent), "build_s": round(build, 2),
           "sim_s": round(sim, 2), "wall_s": round(wall, 3), "driver_s": round(driving, 3),
           "full_sim_per_wall": round(sim / wall, 2), "env_sim_per_wall": round(sim / (wall - driving), 2),
           "full_sim_per_cpu": round(sim / cpu, 2), "outcomes": outcomes, "load_start": round(load, 2),
           "load_end": round(os.getloadavg()[0], 2)}
    if wait:
        return out
    phys_rate = steps / phys * model.opt.timestep  # [sim s / wall s]
    cam_rate = frames / cam * base.dt
    ceiling = 1.0 / (1.0 / phys_rate + 1.0 / cam_rate)
    out.update(physics_steps_per_s=round(steps / phys), physics_sim_per_wall=round(phys_rate, 1),
               camera_frames_per_s=round(frames / cam), camera_sim_per_wall=round(cam_rate, 1),
               ceiling_sim_per_wall=round(ceiling, 1), ceiling_over_full=round(ceiling / (sim / wall), 2),
               ngeom=int(model.ngeom), nbody=int(model.nbody), timestep=float(model.opt.timestep),
               control_period=float(base.dt))
    env.close()
    return out


def _commit(tree: Path) -> str:
    """The tree's git commit (with ``+changes`` when its tracked files differ from it), or ``?``."""
    try:
        head = subprocess.run(["git", "-C", str(tree), "rev-parse", "--short", "HEAD"], capture_output=True,
                              text=True, check=True).stdout.strip()
        dirty = subprocess.run(["git", "-C", str(tree), "status", "--porcelain", "--untracked-files=no"],
                               capture_output=True, text=True, check=True).stdout.strip()
    except (OSError, subprocess.CalledProcessError):
        return "?"
    return head + ("+changes" if dirty else "")


def _spawn(tree: Path, args, wait: bool) -> subprocess.Popen:
    env = dict(os.environ, PYTHONPATH=str(tree))
    cmd = [sys.executable, str(Path(__file__).resolve()), "--probe", "--map", args.map,
           "--garage-seed", str(args.garage_seed), "--tests", str(args.tests)] + (["--wait"] if wait else [])
    return subprocess.Popen(cmd, cwd=tree, env=env, stdin=subprocess.PIPE, stdout=subprocess.PIPE, text=True)


def _result(proc: subprocess.Popen) -> dict:
    out, _ = proc.communicate()
    if proc.returncode:
        raise SystemExit(f"probe failed (exit {proc.returncode}); run it alone with --probe to see why")
    return json.loads(out.strip().splitlines()[-1])


def run_probes(tree: Path, args, workers: int) -> dict:
    """``workers`` probes of ``tree`` at once; one worker also measures physics and camera alone."""
    if workers == 1:
        return _result(_spawn(tree, args, wait=False))
    procs = [_spawn(tree, args, wait=True) for _ in range(workers)]
    for p in procs:
        assert p.stdout.readline().strip() == "ready"
    for p in procs:
        p.stdin.write("go\n")
        p.stdin.flush()
    rows = [_result(p) for p in procs]
    sim, wall = sum(r["sim_s"] for r in rows), max(r["wall_s"] for r in rows)
    return {"workers": workers, "sim_s": sim, "wall_s": wall, "full_sim_per_wall": round(sim / wall, 2),
            "per_worker": [r["full_sim_per_wall"] for r in rows],
            "per_worker_cpu": [r["full_sim_per_cpu"] for r in rows], "load_start": rows[0]["load_start"],
            "load_end": max(r["load_end"] for r in rows)}


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--map", default="m5_13x13_aligned")
    ap.add_argument("--garage-seed", type=int, default=1)
    ap.add_argument("--tests", type=int, default=10, help="seeded vision tests per probe (default 10)")
    ap.add_argument("--rounds", type=int, default=3, help="interleaved rounds; medians are reported (default 3)")
    ap.add_argument("--workers", type=int, nargs="*", default=[1, 2], help="worker counts to measure (default 1 2)")
    ap.add_argument("--baseline-tree", type=Path, default=None, help="another checkout to measure alongside")
    ap.add_argument("--json", type=Path, default=None, help="write the results here (e.g. docs/bench_drive_env.json)")
    ap.add_argument("--probe", action="store_true", help=argparse.SUPPRESS)
    ap.add_argument("--wait", action="store_true", help=argparse.SUPPRESS)
    args = ap.parse_args(argv)
    if args.probe:
        print(json.dumps(probe(args.map, args.garage_seed, args.tests, args.wait)))
        return 0
    prov = provenance(argv)  # before the run: the load it starts at
    trees = {"after": HERE}
    if args.baseline_tree is not None:
        if not (args.baseline_tree / "garage_mj" / "__init__.py").is_file():
            raise SystemExit(f"--baseline-tree {args.baseline_tree}: no garage_mj package there; give a checkout")
        trees["before"] = args.baseline_tree.resolve()
    rounds: list[dict] = []
    for k in range(args.rounds):
        order = list(trees) if k % 2 == 0 else list(trees)[::-1]  # alternate who goes first
        row = {}
        for name in order:
            for w in args.workers:
                row[f"{name}_w{w}"] = r = run_probes(trees[name], args, w)
                extra = (f"physics {r['physics_steps_per_s']} steps/s ({r['physics_sim_per_wall']}), camera "
                         f"{r['camera_frames_per_s']} frames/s ({r['camera_sim_per_wall']}), ceiling "
                         f"{r['ceiling_sim_per_wall']}, ceiling/full {r['ceiling_over_full']}") if w == 1 else \
                    f"per worker {r['per_worker']} (per CPU s {r['per_worker_cpu']})"
                print(f"round {k + 1} {name:6s} workers {w}: full {r['full_sim_per_wall']} sim s/wall s; {extra}; "
                      f"load {r['load_start']}-{r['load_end']}", flush=True)
        rounds.append(row)
    summary = {}
    for name in trees:
        one = [r[f"{name}_w1"] for r in rounds] if 1 in args.workers else []
        s = {}
        if one:
            for key in ("full_sim_per_wall", "env_sim_per_wall", "full_sim_per_cpu", "physics_steps_per_s",
                        "physics_sim_per_wall",
                        "camera_frames_per_s", "camera_sim_per_wall", "ceiling_sim_per_wall", "ceiling_over_full"):
                s[key] = statistics.median(r[key] for r in one)
            s["driver_share"] = round(statistics.median(r["driver_s"] / r["wall_s"] for r in one), 3)
        for w in args.workers:
            if w != 1 and 1 in args.workers:
                s[f"scaling_w{w}"] = round(statistics.median(
                    r[f"{name}_w{w}"]["full_sim_per_wall"] / r[f"{name}_w1"]["full_sim_per_wall"] for r in rounds), 2)
                # per CPU second each worker got: do the workers slow each other, or does the machine lack cores?
                s[f"cpu_rate_w{w}_over_w1"] = round(statistics.median(
                    statistics.mean(r[f"{name}_w{w}"]["per_worker_cpu"]) / r[f"{name}_w1"]["full_sim_per_cpu"]
                    for r in rounds), 2)
        summary[name] = s
    if "before" in trees and 1 in args.workers:
        summary["after_over_before"] = {key: round(statistics.median(
            r["after_w1"][key] / r["before_w1"][key] for r in rounds), 2)
            for key in ("full_sim_per_wall", "full_sim_per_cpu", "physics_steps_per_s", "camera_frames_per_s")}
    print(json.dumps(summary, indent=2))
    if args.json:
        args.json.parent.mkdir(parents=True, exist_ok=True)
        meta = {"command": " ".join(["eval/bench_drive_env.py", *(argv if argv is not None else sys.argv[1:])]),
                "map": args.map, "garage_seed": args.garage_seed, "tests": args.tests, "rounds": args.rounds,
                "cpus": os.cpu_count(), "when": time.strftime("%Y-%m-%d %H:%M:%S %Z"),
                "trees": {name: {"path": str(tree), "commit": _commit(tree)} for name, tree in trees.items()}}
        args.json.write_text(json.dumps({"meta": meta, "summary": summary, "rounds": rounds,
                                          "provenance": prov}, indent=2) + "\n")
    return 0


if __name__ == "__main__":
    sys.exit(main())
