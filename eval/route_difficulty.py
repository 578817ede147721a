"""Issue 21's validation of the route-aware difficulty: fit on some garages and drivers, test on others.

Protocol (fixed before any result was seen; nothing is tuned on the held-out sets):

* **fit set**: ``--fit-per-map`` garages of each 13x13 map (m4, m5, m6, m7) from the DQN runs with
  training seeds ``--fit-run-seeds`` (default 0-3) of ``--library``, stratified by the paper's
  difficulty, ``--fit-tests`` cruise tests each with the fit drivers (default ``vision`` and
  ``waypoint``, the paper's discrete actions, occupancy 0.5). The route difficulty is fitted on
  these tests' outcomes (``garage-mj difficulty fit``).
* **held-out garages**: 50 m5 garages of the run with training seed ``--heldout-run-seed`` (default
  4; no fit garage comes from it), 50 tests each, exactly ``eval/paper_validation.py --run-seeds 4``.
* **held-out driver**: ``learned`` (the shipped deep-RL model, never in the fit) on the held-out
  garages; the fit drivers on the held-out garages are the garage-only hold-out.

For each held-out (driver, set) it prints and writes the per-garage Pearson r between success %
and (a) the route difficulty, (b) the paper's difficulty, each with a 95 % bootstrap interval over
garages, and the per-test AUC of each as a failure predictor. Every cruise run is resumable
(re-run the same command); ``--reuse DRIVER=DIR`` copies the tests of an earlier identical run
(for example ``runs/paper_validation_vision``) instead of driving them again.

    .venv/bin/python eval/route_difficulty.py --library runs/paper_10pct/library.sqlite \\
        --out runs/route_difficulty --json docs/route_difficulty/validation.json
"""

from __future__ import annotations

import argparse
import shutil
import sys
from pathlib import Path

from garage_mj.cli._common import positive_int, seed_list

FIT_MAPS = ("m4_13x13_offset", "m5_13x13_aligned", "m6_13x13_s", "m7_13x13_u")
HELDOUT_MAP = "m5_13x13_aligned"
FIT_DRIVERS = ("vision", "waypoint")
HELDOUT_DRIVERS = ("vision", "waypoint", "learned")


def collect(library: Path, out: Path, drivers, maps, run_seeds, per_map: int, tests: int, workers: int,
            tag: str, reuse: dict[str, Path] | None = None) -> dict[str, Path]:
    """Run (resumably) ``tests`` discrete cruise tests of each driver on the garages; returns driver -> run folder."""
    from garage_mj.driving.garage_set import GarageSet
    from garage_mj.reporting.cruise import run_cruise

    sources = []
    for m in maps:
        sources += list(GarageSet.from_library(library, map=m, run_seeds=run_seeds, n=per_map, seed=0))
    runs = {}
    for driver in drivers:
        run = out / f"{tag}_{driver}"
        if reuse and driver in reuse and not (run / "tests.csv").exists():
            run.mkdir(parents=True, exist_ok=True)
            for name in ("tests.csv", "run.json"):
                shutil.copy(reuse[driver] / name, run / name)
        print(f"{tag}: {len(sources)} garages x {tests} tests, driver {driver} -> {run}", flush=True)
        run_cruise(sources, tests, driver, workers, 0, run, action_type="discrete")
        runs[driver] = run
    return runs


def _reuse(items: list[str]) -> dict[str, Path]:
    out = {}
    for item in items:
        driver, _, path = item.partition("=")
        if not path or not (Path(path) / "tests.csv").is_file():
            raise SystemExit(f"--reuse {item!r}: expected DRIVER=DIR with DIR/tests.csv")
        out[driver] = Path(path)
    return out


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--library", type=Path, required=True, help="DQN library with runs of seeds 0-4 of the 13x13 maps")
    p.add_argument("--out", type=Path, default=Path("runs/route_difficulty"))
    p.add_argument("--json", type=Path, help="write the figures here")
    p.add_argument("--fit-run-seeds", type=seed_list, default=[0, 1, 2, 3], metavar="K,K")
    p.add_argument("--fit-per-map", type=positive_int, default=12)
    p.add_argument("--fit-tests", type=positive_int, default=20)
    p.add_argument("--heldout-run-seed", type=int, default=4)
    p.add_argument("--heldout-garages", type=positive_int, default=50)
    p.add_argument("--heldout-tests", type=positive_int, default=50)
    p.add_argument("--heldout-drivers", default=",".join(HELDOUT_DRIVERS))
    p.add_argument("--reuse", nargs="*", default=[], metavar="DRIVER=DIR",
                   help="held-out runs done before with the same settings (e.g. vision=runs/paper_validation_vision)")
    p.add_argument("--workers", type=positive_int, default=2)
    p.add_argument("--only", choices=("fit", "heldout"), help="only collect this part's cruise tests")
    args = p.parse_args(argv)
    if args.heldout_run_seed in args.fit_run_seeds:
        p.error("--heldout-run-seed must not be one of --fit-run-seeds")
    if args.only in (None, "fit"):
        collect(args.library, args.out, FIT_DRIVERS, FIT_MAPS, args.fit_run_seeds, args.fit_per_map,
                args.fit_tests, args.workers, "fit")
    if args.only in (None, "heldout"):
        collect(args.library, args.out, args.heldout_drivers.split(","), (HELDOUT_MAP,), [args.heldout_run_seed],
                args.heldout_garages, args.heldout_tests, args.workers, "heldout", _reuse(args.reuse))
    if args.only is not None:
        return 0
    raise SystemExit("fit and report: not written yet")


if __name__ == "__main__":
    sys.exit(main())
