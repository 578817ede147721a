"""``garage-mj hunt``: spend a budget of cruise tests to find the garages where a driver fails."""

from __future__ import annotations

import argparse
from pathlib import Path

from garage_mj.cli import UserError
from garage_mj.cli._common import compute, int_in, positive_int, seed, unit_range
from garage_mj.cli.cruise import (
    MAX_WORKERS,
    action_warnings,
    add_actor_arguments,
    add_task_args,
    built_in_drivers,
    runner_failures,
    scenario,
    task_warning,
    test_seconds,
)
from garage_mj.driving.hunt import (
    MAX_BUDGET,
    MAX_POPULATION,
    PARK_HUNT_GEOMETRIES,
    HuntConfig,
    HuntResult,
    variant_label,
)
from garage_mj.driving.sources import DEFAULT_TEST_TIMEOUT, MAX_TEST_TIMEOUT, MAX_TESTS, CruiseSettings
from garage_mj.reporting.report import task_noun


def register(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser(
        "hunt", help="search for the garages where a driver fails, with files to reproduce each failure",
        description="An elitist evolution over garages: start from a library's garages (or painted ones of a "
                    "map), test each, re-test the best and mutate them under the painter's rules, until --budget "
                    "cruise tests are spent. Writes OUT/failures.csv (garages ranked by failure rate, with what was "
                    "hit and where), OUT/hunt.sqlite, asset packs, .xosc files and MP4s of the worst garages, and "
                    "OUT/report.html. A park or AVP hunt (--task) searches park geometries and stalls too: a child "
                    "may aim every test at a stall where its parent failed, or one beside it; with actors, it may "
                    "keep the scene of a test where the car hit one and place the actors anew. Resumable: run the "
                    "same command again.",
        epilog="example: garage-mj hunt --driver vision --map m5_13x13_aligned --budget 1000 --out hunt_vision")
    src = p.add_mutually_exclusive_group(required=True)
    src.add_argument("--map", help="start from garages painted on this shipped map (name) or map file")
    src.add_argument("--library", type=Path, metavar="FILE", help="start from garages drawn from this library")
    p.add_argument("--library-map", metavar="NAME", help="with --library: only garages of this map")
    p.add_argument("--driver", default="vision",
                   help=f"built-in driver ({built_in_drivers()}; learned: the shipped deep-RL model), "
                        "learned:PATH (a model zip of garage-mj train-driver), module:Class (a module on the Python path or "
                        "in the current folder) or path/to/file.py:Class (default vision)")
    p.add_argument("--budget", type=int_in(1, MAX_BUDGET), default=1000,
                   help=f"cruise tests to spend in all, 1 to {MAX_BUDGET:,} (default 1000)")
    p.add_argument("--tests", type=int_in(1, MAX_TESTS), default=5,
                   help=f"tests per garage per evaluation, 1 to {MAX_TESTS:,} (default 5)")
    p.add_argument("--population", type=int_in(1, MAX_POPULATION), default=20,
                   help=f"garages per generation, 1 to {MAX_POPULATION:,} (default 20)")
    p.add_argument("--elites", type=int_in(1, MAX_POPULATION), default=5,
                   help="best garages kept and mutated, fewer than --population (default 5)")
    p.add_argument("--worst", type=positive_int, default=5,
                   help="garages exported with pack, .xosc and MP4 (default 5)")
    p.add_argument("--no-videos", action="store_true", help="skip the MP4s")
    p.add_argument("--seed", type=seed, default=0, help="hunt seed: start garages, mutations, test seeds")
    p.add_argument("--action-type", choices=("discrete", "continuous"), default=None,
                   help="the paper's 4 actions or [throttle, steer] (default: the driver's own; the hand-written "
                        "built-ins are made for continuous, learned for discrete, a module:Class without an "
                        "action_type attribute is taken as discrete); another one than the driver's own is warned about")
    p.add_argument("--occupancy", type=unit_range, default=0.5, help="share of stalls with a parked car")
    p.add_argument("--test-timeout", type=test_seconds, default=DEFAULT_TEST_TIMEOUT, metavar="SECONDS",
                   help=f"wall time a test may take, at most {MAX_TEST_TIMEOUT:,.0f} s (default "
                        f"{DEFAULT_TEST_TIMEOUT:g} s); past it the test is a "
                        "driver_timeout, as garage-mj cruise")
    add_actor_arguments(p.add_argument_group("adverse events, as garage-mj cruise (a park hunt searches their "
                                             "placements)"))
    p.add_argument("--workers", type=int_in(1, MAX_WORKERS), default=1,
                   help=f"worker processes, 1 to {MAX_WORKERS:,} (default 1)")
    p.add_argument("--backend", choices=("local", "ray"), default="local",
                   help="where the tests run: local processes (default) or Ray (a private local Ray, or the "
                        "cluster at --address); results are the same")
    p.add_argument("--address", metavar="HOST:PORT", help="with --backend ray: a running Ray cluster")
    p.add_argument("--out", type=Path, default=Path("hunt"), help="output folder (default ./hunt)")
    add_task_args(p)
    p.add_argument("--geometries", metavar="NAMES", type=lambda v: [n.strip() for n in v.split(",") if n.strip()],
                   help="park and avp hunts: the park geometries searched, comma-separated names (docs/spec.md "
                        f"section 9; default {','.join(PARK_HUNT_GEOMETRIES)}); a failure counts when the oracle "
                        "parks that test")
    p.add_argument("--quiet", action="store_true", help="no progress bar")
    p.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    from garage_mj.driving.cruise import check_task
    from garage_mj.reporting.hunt import hunt  # matplotlib and MuJoCo, for the figure and the videos

    if args.library is not None and not args.library.is_file():
        raise UserError(f"--library {args.library}: no such file; build one with garage-mj train or generate")
    if args.map is not None and args.library_map is not None:
        raise UserError("--library-map filters a --library; with --map give the map itself")
    # every garage-mj error (config, driver, hunt, backend) is printed as one line by garage_mj.cli.main
    scen = scenario(args)
    env = {} if scen is None else {"scenario": scen}
    cfg = HuntConfig(budget=args.budget, tests=args.tests, population=args.population, elites=args.elites,
                     worst=args.worst)
    with action_warnings("hunt"):
        settings = CruiseSettings(args.driver, args.seed, args.action_type, args.occupancy, env,
                                  test_timeout=args.test_timeout, task=args.task, maneuver=args.maneuver)
        check_task(settings)  # refused before the warning below, as hunt would
        task_warning("hunt", args.driver, args.task)
        res = hunt(settings, args.out, map=args.map if args.library is None else args.library_map,
                   library=args.library, config=cfg, compute=compute(args), videos=not args.no_videos,
                   geometries=args.geometries)
    print(failure_summary(res, task=args.task))
    print(f"ranking: {res.files['failures']}; report: {res.files['report']}")
    return 0


def _n(count: int, noun: str) -> str:
    return f"{count} {noun}{'' if count == 1 else 's'}"


def failure_summary(res: HuntResult, show: int = 5, task: str = "cruise") -> str:
    """The closing lines: tests (a park or AVP hunt's named so: ``40 park tests``), garages, the action type, how
    many garages failed, and the worst of those (a park or AVP hunt's: with its geometry, counting the failures the
    oracle parks)."""
    failing = [s for s in res.ranked if s.confirmed]  # ranked worst first
    test = "test" if task == "cruise" else f"{task_noun(task)} test"
    park = any(s.geometry for s in res.ranked)
    head = (f"{_n(res.tests, test)} on {_n(len(res.ranked), 'garage' if not park else 'garage-geometry pair')} in "
            f"{_n(res.generations, 'generation')} ({res.action_label}); "
            + (f"{_n(len(failing), 'pair')} with a failure the oracle parks" if park
               else f"{_n(len(failing), 'garage')} with a failure"))
    if len(failing) > show:
        head += f", the {show} worst:"
    elif failing:
        head += ":"
    lines = [head] + [f"  {s.source.name}{' (' + variant_label(s.geometry) + ')' if s.geometry else ''}: "
                      f"{len(s.confirmed)} of "
                      f"{len(s.feasible)} feasible tests failed ({100 * s.rate:.0f}%)" for s in failing[:show]]
    kinds = [r["outcome"] for s in res.ranked for r in s.failures]
    lost = runner_failures({k: kinds.count(k) for k in set(kinds)})
    if lost:
        lines.append(f"{lost}: the driver's process died or hung (reasons in {res.out_dir / 'cruise' / 'tests.csv'})")
    return "\n".join(lines)
