"""``garage-mj cruise --cases PATH...``: park tests defined by problem files (docs/spec.md section 9, "Cases from
elsewhere"): TPCAP's case files and this project's park problems, one park test each (:mod:`garage_mj.driving.cases`)."""

from __future__ import annotations

import argparse
from collections.abc import Callable
from contextlib import AbstractContextManager

from garage_mj.cli import UserError
from garage_mj.cli._common import GEOMETRY_KEYS, compute
from garage_mj.driving.results import BREAKDOWNS, breakdown_lines
from garage_mj.driving.sim.outcomes import RUNNER_KINDS
from garage_mj.scene.vehicles import DEFAULT_VEHICLE

#: Options of ``cruise`` that choose garages or shape a garage's tests: a run of cases has neither.
_NOT_FOR_CASES = (("sample", "--sample"), ("ids", "--ids"), ("map", "--map"), ("difficulty", "--difficulty"),
                  ("coverage", "--coverage"), ("route_difficulty", "--route-difficulty"), ("feasible", "--feasible"),
                  ("limit", "--limit"), ("route_model", "--route-model"), ("stall", "--stall"),
                  ("pedestrians", "--pedestrians"), ("moving_cars", "--moving-cars"), ("clutter", "--clutter"),
                  ("scenario", "--scenario"))


def refuse_options(args: argparse.Namespace) -> None:
    """One line for an option a run of cases does not take (before anything is read or written)."""
    for attr, flag in _NOT_FOR_CASES:
        if getattr(args, attr, None) is not None:
            raise UserError(f"{flag} does not apply to --cases (each case file is one park test of its own); "
                            "leave it out")
    for attr, flag in (("xosc", "--xosc"), ("videos", "--videos"), ("report", "--report")):
        if getattr(args, attr, None):
            raise UserError(f"{flag} is for garage runs (--packs or --library), not --cases; leave it out")
    for attr in (*GEOMETRY_KEYS, "layout"):
        if getattr(args, attr, None) is not None:
            raise UserError(f"--{attr.replace('_', '-')} does not apply to --cases: a case's obstacles are its own "
                            "geometry; leave it out")
    if args.vehicle != DEFAULT_VEHICLE:
        raise UserError(f"--vehicle {args.vehicle}: a case brings its own vehicle (TPCAP's car, or the park problem's "
                        "car); leave --vehicle out")
    if args.parked_fleet != "uniform" or args.parked_jitter:
        raise UserError("--parked-fleet and --parked-jitter draw a garage's parked cars; a case's are its obstacles: "
                        "leave them out")
    if args.task == "avp":
        raise UserError("--task avp: a case is a park test (it starts where the parking starts); leave --task out")


def run_cases_cli(args: argparse.Namespace, action_warnings: Callable[[str], AbstractContextManager],
                  task_warning: Callable[[str, str, str], None]) -> int:
    """Read every case (a bad file: one line, nothing written), drive each with ``--driver``, print the counts;
    ``action_warnings`` and ``task_warning``: ``cruise``'s (:mod:`garage_mj.cli.cruise`)."""
    from garage_mj.driving.cases import case_settings, read_cases, run_cases, stats_line
    from garage_mj.driving.cruise import check_task

    refuse_options(args)
    cases = read_cases(args.cases)
    if args.out.exists() and not args.out.is_dir():
        raise UserError(f"--out {args.out} is a file, not a folder; choose another path")
    args.driver = args.driver or "vision"
    with action_warnings("cruise"):
        settings = case_settings(args.driver, args.seed, args.action_type, test_timeout=args.test_timeout)
        check_task(settings)
        task_warning("cruise", args.driver, "park")
        res = run_cases(cases, settings, args.out, compute=compute(args), park_model=args.park_model or True)
    print(stats_line(res))
    for line in breakdown_lines({k: res.stats[k] for k in BREAKDOWNS if k in res.stats}):
        print(f"  {line}")
    for row in res.rows:
        if row["outcome"] != "success":
            print(f"  {row['garage']}: {row['outcome']}{' (' + row['hit'] + ')' if row['hit'] else ''}: {row['reason']}")
    lost = ", ".join(f"{res.stats['failures'][k.value]} {k.value}" for k in RUNNER_KINDS
                     if res.stats["failures"].get(k.value))
    if lost:
        print(f"{lost}: the driver's process died or hung (reasons in {res.out_dir / 'tests.csv'})")
    return 0
