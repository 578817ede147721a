"""``garage-mj demo``: the main job end to end on a small garage, with an HTML report."""

from __future__ import annotations

import argparse

from garage_mj.cli._common import MAX_WORKERS, int_in, non_negative_int, positive_int, seed
from garage_mj.core.fsutil import FolderLock
from garage_mj.reporting.demo import DemoConfig, demo_config, run_demo

_D = DemoConfig()


def register(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser(
        "demo",
        help="the main job end to end on a small garage, with an HTML report",
        description=(
            f"Train DQN on a map (short run, {len(_D.train_seeds)} seeds), fill a scenario library with every "
            "usable garage, export asset packs for a difficulty-stratified sample, run cruise tests with the "
            "built-in drivers (oracle, waypoint, vision, and learned: the shipped DQN), each with the action type it is made for, "
            f"then park tests ({' and '.join(_D.park_maneuvers)}) and AVP tests with the {' and '.join(_D.park_drivers)} "
            f"drivers on {_D.park_garages} of the garages, and write "
            "OUT/report.html: figures, garages, the cruise table, the park section (success by driver and task, by "
            "level and maneuver), the failures' reasons per class with links to "
            "each run's tests.csv and to an MP4 and a .xosc of the first failures (a park failure's top-down "
            "picture). Stages resume: re-running "
            "reuses finished training, complete packs, finished tests and recorded videos."
        ),
    )
    p.add_argument("--map", default=_D.map, help=f"shipped map name or map file (default: {_D.map})")
    p.add_argument("--timesteps", type=positive_int, default=_D.timesteps,
                   help=f"DQN timesteps per training seed (default: {_D.timesteps})")
    p.add_argument("--garages", type=positive_int, default=_D.garages,
                   help=f"garages to export and test (default: {_D.garages})")
    p.add_argument("--tests", type=positive_int, default=_D.tests,
                   help=f"cruise tests per garage and driver (default: {_D.tests})")
    p.add_argument("--videos", type=non_negative_int, default=_D.failure_videos,
                   help="failures shown per driver run, each with an MP4 and its .xosc "
                        f"(default: {_D.failure_videos}; 0: none)")
    p.add_argument("--workers", type=int_in(1, MAX_WORKERS), default=_D.workers,
                   help=f"cruise worker processes, 1 to {MAX_WORKERS:,} (default: {_D.workers})")
    p.add_argument("--seed", type=seed, default=_D.seed, help=f"seed of sampling and tests (default: {_D.seed})")
    p.add_argument("--out", default=_D.out, help=f"output folder (default: {_D.out})")
    p.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    cfg = demo_config(map=args.map, timesteps=args.timesteps, garages=args.garages, tests=args.tests,
                      failure_videos=args.videos, workers=args.workers, seed=args.seed, out=args.out)
    with FolderLock(cfg.out, "garage-mj demo", remove=True):  # a second demo into the same --out is refused
        report = run_demo(cfg)
    print(f"open {report} in a browser")
    return 0
