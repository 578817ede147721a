"""Does a hard training ground help the parking driver? Fine-tune it on uniformly drawn or on generated hard garages.

Two arms at the same budget, ``--seeds`` runs each, compared on one held-out hard set with 95% intervals:

- **the grounds**: per park geometry (``--geometries``), the m5 generator (``garage-mj generate --metric park``'s
  own :func:`~garage_mj.generation.generator.generate`, rated by ``--park-model``) paints ``--probe`` garages with
  no band on the park difficulty (the **uniform** arm's draw: its first ``--per-geometry`` are the arm's
  garages), then ``--per-geometry`` garages in the band ``[q, 1]``, ``q`` the 75th percentile of that geometry's
  probe (the **hard** arm: harder than three quarters of what the generator paints in that geometry). Both arms
  get the same geometry mix: garage ``k`` is built in the ``(k mod n)``-th geometry, in which it was rated.
- **the held-out hard set**: the same band per geometry, another generation seed, garages of neither arm nor
  the shipped model's training and validation sets (:data:`SHIPPED_SETS`); ``--tests`` park tests per garage (maneuver drawn per test,
  half the other stalls occupied).
- **the training**: each run goes on from the parking model's first run at its best iteration (``--init``,
  ``garage-mj train-driver --init RUN/checkpoints/iter_NNN.zip`` with ``models/drivers/park_m5.toml``: its network
  and the states it was fitted on) with DAgger for ``--iterations`` x ``--steps`` on its arm's garages, the
  oracle's share ``--beta0`` per step at the first iteration (halved each one), no validation (the last
  iteration is the run's model). The model it starts from, not trained further, is scored too.

Everything is in ``--runs`` (grounds, runs, test folders): the same command resumes where it stopped. The JSON has
per model and pooled per arm: success over driven tests with a 95% Wilson interval, collisions, outcomes; and the
difference of the arms' pooled success with a 95% interval (Newcombe's hybrid score interval).

    MUJOCO_GL=egl .venv/bin/python eval/hard_training_ground.py --workers 2 --json docs/hard_training_ground.json
"""

from __future__ import annotations

import argparse
import csv
import json
import math
import statistics
import sys
import time
from pathlib import Path

from _provenance import provenance  # eval/_provenance.py: command, date, machine, commit
from bench_learned_park import stats, wilson

from garage_mj.core.backends import Compute
from garage_mj.core.config import load_config
from garage_mj.driving.cruise import run_cruise
from garage_mj.driving.garage_set import GarageSet, load_garage_set
from garage_mj.driving.learning.saved_model import PARK_MODEL
from garage_mj.driving.learning.train import DriverTrainConfig, train_driver
from garage_mj.driving.park_geometries import PARK_GEOMETRIES
from garage_mj.driving.sources import CruiseSettings, CruiseSource
from garage_mj.generation.generator import RouteMetric, generate
from garage_mj.scene.park_rating import ParkRater, load_park_model
from garage_mj.scene.world import world_with

ROOT = Path(__file__).resolve().parents[1]
ARMS = ("uniform", "hard")
MAP = "m5_13x13_aligned"
#: The parking model's training and validation garages (its first run's folder, where this machine has it): never
#: held out.
SHIPPED_SETS = (ROOT / "runs" / "park_m5" / "garages.json", ROOT / "runs" / "park_m5" / "validation_garages.json")


def _generated(lib: Path, rater: ParkRater, band: tuple[float, float], count: int, seed: int) -> list[CruiseSource]:
    """``count`` garages of :data:`MAP` whose park difficulty under ``rater`` lies in ``band``, generated into
    ``lib`` (kept: a second call reads them back), in library order."""
    if not lib.exists():
        generate(MAP, band, count, lib, seed=seed, progress=False, route=RouteMetric(rater, rater.key, "park difficulty"))
    return list(GarageSet.from_library(lib))[:count]


def grounds(args: argparse.Namespace, model) -> dict:
    """The arms' training garages (interleaved by geometry), the held-out hard set per geometry, and each
    geometry's band (module docstring)."""
    out = args.runs / "grounds"
    out.mkdir(parents=True, exist_ok=True)
    shipped = {s.hash for f in SHIPPED_SETS if f.exists() for s in load_garage_set(str(f))}
    per: dict[str, dict] = {}
    for i, g in enumerate(args.geometries):
        rater = ParkRater(world_with(PARK_GEOMETRIES[g].world or None, f"park geometry {g}"), model)
        probe = _generated(out / f"uniform_{g}.sqlite", rater, (0.0, 1.0), args.probe, args.seed + 10 * i)
        values = [rater(s.garage) for s in probe]
        q = statistics.quantiles(values, n=4)[2]
        band = (round(q, 4), 1.0)
        hard = _generated(out / f"hard_{g}.sqlite", rater, band, args.per_geometry, args.seed + 10 * i + 1)
        taken = {s.hash for s in probe[: args.per_geometry]} | {s.hash for s in hard} | shipped
        pool = _generated(out / f"heldout_{g}.sqlite", rater, band, args.heldout + args.per_geometry,
                          args.seed + 10 * i + 1_000)
        held = [s for s in pool if s.hash not in taken][: args.heldout]
        per[g] = {"band": band, "probe_values": [round(v, 4) for v in values],
                  "uniform": probe[: args.per_geometry], "hard": hard, "heldout": held,
                  "values": {"uniform": [round(v, 4) for v in values[: args.per_geometry]],
                             **{k: [round(rater(s.garage), 4) for s in v] for k, v in (("hard", hard), ("heldout", held))}}}
        print(f"{g}: band [{band[0]:.3f}, 1]; uniform mean {statistics.fmean(per[g]['values']['uniform']):.3f}, "
              f"hard {statistics.fmean(per[g]['values']['hard']):.3f}, held out "
              f"{statistics.fmean(per[g]['values']['heldout']):.3f} ({len(held)} garages)", flush=True)
    return per


def interleaved(per: dict, arm: str) -> GarageSet:
    """The arm's garages in the order that builds garage ``k`` in the ``(k mod n)``-th geometry."""
    geoms = list(per)
    n = min(len(per[g][arm]) for g in geoms)
    return GarageSet([per[g][arm][j] for j in range(n) for g in geoms],
                     f"{arm} ground: {n} generated {MAP} garages per park geometry ({', '.join(geoms)})")


def train(args: argparse.Namespace, per: dict) -> dict[str, Path]:
    """Each arm's fine-tuned models, by ``arm/seed``."""
    cfg = load_config(DriverTrainConfig, ROOT / "models" / "drivers" / f"{PARK_MODEL}.toml",
                      iterations=args.iterations, steps_per_iteration=args.steps, val_tests=0, beta0=args.beta0,
                      geometries=tuple(per))
    models = {}
    for arm in ARMS:
        garages = interleaved(per, arm)
        for seed in range(args.seeds):
            out = args.runs / "train" / f"{arm}_s{seed}"
            t0 = time.perf_counter()
            models[f"{arm}/s{seed}"] = train_driver(garages, out, config=cfg, seed=seed, progress=False,
                                                    init=args.init)
            wall = json.loads((out / "run.json").read_text())["state"]["wall_s"]
            print(f"trained {arm} seed {seed}: {wall / 60:.1f} min of iterations ({time.perf_counter() - t0:.0f} s "
                  "this call)", flush=True)
    return models


def evaluate(args: argparse.Namespace, per: dict, name: str, model: Path) -> list[dict]:
    """``model``'s park tests on the held-out hard set (tests.csv rows, tagged with their geometry)."""
    rows = []
    for g in per:
        folder = args.runs / "test" / name.replace("/", "_") / g
        settings = CruiseSettings(driver=f"learned:{model}", seed=args.seed, task="park", maneuver="any",
                                  env=PARK_GEOMETRIES[g].env_kwargs())
        run_cruise(per[g]["heldout"], args.tests, settings, folder, compute=Compute(workers=args.workers, progress=False),
                   route_model=False)
        got = list(csv.DictReader((folder / "tests.csv").open()))
        rows += [{**r, "geometry": g} for r in got]
    s = stats(rows)
    print(f"{name:12s} {s['success']}/{s['driven']} ({s['success_pct']}%) {s['outcomes']}", flush=True)
    return rows


def difference(k1: int, n1: int, k2: int, n2: int) -> list[float] | None:
    """Newcombe's 95% interval of p1 - p2 from the two Wilson intervals [percentage points]."""
    if not n1 or not n2:
        return None
    p1, p2 = k1 / n1, k2 / n2
    l1, u1 = (x / 100 for x in wilson(k1, n1))
    l2, u2 = (x / 100 for x in wilson(k2, n2))
    lo = p1 - p2 - math.sqrt((p1 - l1) ** 2 + (u2 - p2) ** 2)
    hi = p1 - p2 + math.sqrt((u1 - p1) ** 2 + (p2 - l2) ** 2)
    return [round(100 * lo, 1), round(100 * hi, 1)]


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--geometries", nargs="*", choices=sorted(PARK_GEOMETRIES),
                    default=["default", "tight", "angled60", "angled45", "parallel"])
    ap.add_argument("--park-model", default="learned_park", help="the park difficulty the grounds are rated by")
    ap.add_argument("--probe", type=int, default=24, help="uniform garages painted per geometry (default 24)")
    ap.add_argument("--per-geometry", type=int, default=8, help="training garages per arm and geometry (default 8)")
    ap.add_argument("--heldout", type=int, default=6, help="held-out hard garages per geometry (default 6)")
    ap.add_argument("--tests", type=int, default=2, help="park tests per held-out garage (default 2)")
    ap.add_argument("--seeds", type=int, default=3, help="training runs per arm (default 3)")
    ap.add_argument("--iterations", type=int, default=1, help="DAgger iterations per run (default 1)")
    ap.add_argument("--steps", type=int, default=8000, help="env steps per iteration (default 8,000, as the shipped run)")
    ap.add_argument("--beta0", type=float, default=0.0625,
                    help="the oracle's share of the first iteration's steps, halved each iteration (default "
                         "0.0625: the model drives 15 of 16 steps, as late in a DAgger run)")
    ap.add_argument("--init", type=Path, default=ROOT / "runs" / "park_m5" / "checkpoints" / "iter_013.zip",
                    help="the model the runs start from (default: the parking model's first run at its best iteration, "
                         "13, which brings its states)")
    ap.add_argument("--workers", type=int, default=2)
    ap.add_argument("--seed", type=int, default=0, help="seed of the grounds and the tests (default 0)")
    ap.add_argument("--runs", type=Path, default=ROOT / "runs" / "hard_training_ground")
    ap.add_argument("--json", type=Path, default=ROOT / "docs" / "hard_training_ground.json")
    args = ap.parse_args(argv)
    prov = provenance(argv)
    t0 = time.perf_counter()
    per = grounds(args, load_park_model(args.park_model))
    models = {"start": args.init, **train(args, per)}
    rows = {name: evaluate(args, per, name, path) for name, path in models.items()}
    arms = {arm: [r for name, got in rows.items() if name.startswith(arm + "/") for r in got] for arm in ARMS}
    pooled = {arm: stats(arms[arm]) for arm in ARMS}
    u, h = pooled["uniform"], pooled["hard"]
    runs = {}
    for name in models:
        if name != "start":
            run = json.loads((args.runs / "train" / name.replace("/", "_") / "run.json").read_text())
            runs[name] = {"wall_s": run["state"]["wall_s"], "states": run["state"]["curve"][-1]["states"],
                          "own_drive_success": [r["own_drive_success"] for r in run["state"]["curve"]]}
    result = {
        "settings": {k: (str(v) if isinstance(v, Path) else v) for k, v in vars(args).items()},
        "grounds": {g: {"band": v["band"], "probe_values": v["probe_values"], "values": v["values"]}
                    for g, v in per.items()},
        "models": {name: stats(got) for name, got in rows.items()},
        "by_geometry": {name: {g: stats([r for r in got if r["geometry"] == g]) for g in per}
                        for name, got in rows.items()},
        "arms": pooled,
        "hard_minus_uniform_pp": {"difference": round(h["success_pct"] - u["success_pct"], 1)
                                  if h["driven"] and u["driven"] else None,
                                  "ci95": difference(h["success"], h["driven"], u["success"], u["driven"])},
        "runs": runs, "wall_s": round(time.perf_counter() - t0, 1), "provenance": prov}
    args.json.parent.mkdir(parents=True, exist_ok=True)
    args.json.write_text(json.dumps(result, indent=1) + "\n")
    d = result["hard_minus_uniform_pp"]
    print(f"held-out hard set: start {result['models']['start']['success_pct']}%, uniform arm {u['success_pct']}% "
          f"{u['ci95_pct']}, hard arm {h['success_pct']}% {h['ci95_pct']}; hard - uniform {d['difference']} pp "
          f"{d['ci95']} -> {args.json}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
