"""The paper's difficulty validation (docs/spec.md sections 5 and 7): cruise tests vs. garage difficulty.

50 garages of ``m5_13x13_aligned`` stratified by difficulty (from ``--library``, or painted by the
scripted painter when none is given), 50 cruise tests each with ``--driver``; prints Pearson
r(difficulty, success %) next to the paper's r = -0.638 and writes the CSVs and regression.png.
``--scale 0.1`` runs 5 garages x 5 tests. Resumable: re-run the same command after a Ctrl-C.

The protocol is the paper's: discrete actions (its 4 actions) unless ``--action-type`` says
otherwise, passed explicitly, so a driver made for continuous actions (the built-ins) gets the
one-line ``ActionTypeWarning``. Failures are printed per outcome class and in the paper's three
classes (collision, timeout, deadlock), where a ``missed_goal`` counts as a deadlock.

    .venv/bin/python eval/paper_validation.py --scale 0.1 --workers 2 --out runs/paper_small
"""

from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path

from garage_mj.cli._common import seed_list
from garage_mj.core.backends import Compute
from garage_mj.driving.difficulty.regression import PAPER_R
from garage_mj.driving.sources import CruiseSettings, CruiseSource, painted_sources
from garage_mj.reporting.cruise import run_cruise

MAP = "m5_13x13_aligned"
GARAGES = 50
TESTS = 50


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--library", type=Path, help="library to sample garages from (default: paint them)")
    p.add_argument("--scale", type=float, default=1.0, help="fraction of the 50 garages and 50 tests (default 1)")
    p.add_argument("--workers", type=int, default=2)
    p.add_argument("--driver", default="vision",
                   help="built-in driver (oracle, waypoint, vision, learned), learned:PATH (a model zip of "
                        "garage-mj train-driver) or module:Class (default vision)")
    p.add_argument("--action-type", choices=("discrete", "continuous"), default="discrete",
                   help="default discrete: the paper's protocol (the hand-written built-ins' own is continuous, "
                        "learned's discrete)")
    p.add_argument("--run-seeds", type=seed_list, metavar="K,K",
                   help="with --library: only garages of the DQN runs with these seeds (e.g. those a learned "
                        "driver did not train on; sampled the same way, stratified by difficulty)")
    p.add_argument("--seed", type=int, default=0)
    p.add_argument("--out", type=Path, default=Path("runs/paper_validation"))
    args = p.parse_args(argv)
    if not 0 < args.scale <= 1:
        p.error(f"--scale must be in (0, 1], got {args.scale}")
    n_garages = max(2, round(GARAGES * args.scale))
    n_tests = max(2, round(TESTS * args.scale))
    if args.run_seeds is not None and args.library is None:
        p.error("--run-seeds needs --library")
    if args.library is not None and args.run_seeds is not None:
        from garage_mj.driving.garage_set import GarageSet

        sources = list(GarageSet.from_library(args.library, map=MAP, run_seeds=args.run_seeds, n=n_garages,
                                              seed=args.seed))
    elif args.library is not None:
        from garage_mj.generation.library import Library

        with Library(args.library, create=False) as lib:
            sources = [CruiseSource.from_record(r) for r in lib.sample(n_garages, args.seed, map=MAP)]
    if args.library is not None:
        if len(sources) < 2:
            print(f"{args.library} holds fewer than 2 garages of {MAP}", file=sys.stderr)
            return 2
    else:
        sources = painted_sources(MAP, n_garages, args.seed)
    print(f"{len(sources)} garages of {MAP} (difficulty {min(s.difficulty for s in sources):.3f}"
          f"-{max(s.difficulty for s in sources):.3f}) x {n_tests} tests, driver {args.driver} with "
          f"{args.action_type} actions, {args.workers} workers")
    start = time.perf_counter()
    res = run_cruise(sources, n_tests,
                     CruiseSettings(args.driver, seed=args.seed, action_type=args.action_type), args.out,
                     compute=Compute(workers=args.workers))
    wall = time.perf_counter() - start
    s = res.stats
    r = "n/a (constant success or difficulty)" if s["r"] is None else f"{s['r']:.3f}"
    print(f"Pearson r(difficulty, success %) = {r}   paper: {PAPER_R}")
    if s["slope"] is not None:
        print(f"regression: success % = {s['slope']:.1f} * difficulty + {s['intercept']:.1f} (n = {s['n']})")
    print(f"success {s['success_pct']}% of {s['feasible']} feasible tests ({s['infeasible']} infeasible, excluded) "
          f"out of {s['tests']} ({res.action_label}); failures {s['failures']}, collisions by what was hit "
          f"{s['hits']}")
    print(f"in the paper's three classes (a missed_goal counts as a deadlock): {s['paper_failures']}")
    print(f"{res.tests_run} tests run now in {wall:.0f} s ({s['seconds_per_test']} s/test, "
          f"{s['sim_seconds_per_wall_second']} sim s per wall s per worker)")
    print(f"wrote {res.out_dir}/tests.csv, summary.csv, summary.json, regression.png")
    return 0


if __name__ == "__main__":
    sys.exit(main())
