"""``garage-mj plot convergence|heatmap|driver``: the generation stage's figures and a learned driver's curve."""

from __future__ import annotations

import argparse
from pathlib import Path

from garage_mj.cli import UserError
from garage_mj.cli._common import SHIPPED_ROUTE_MODELS, int_in, route_key, user_errors
from garage_mj.generation.library import Library

MAX_SMOOTH = 1_000_000  # [episodes] of --smooth's moving mean


def register(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser("plot", help="convergence curves and difficulty/coverage heatmaps (PNG)")
    psub = p.add_subparsers(dest="plot_command", metavar="FIGURE", required=True)
    c = psub.add_parser(
        "convergence",
        help="return vs episode: mean over runs of each map with a 95%% confidence band",
        description="Reads monitor.csv of each run folder (written by 'garage-mj train'), groups runs by "
        "map, and draws the mean return per episode with a 95% t-interval over the runs (one panel per map).",
    )
    c.add_argument("runs", nargs="+", type=Path, metavar="RUN", help="run folders (or their monitor.csv)")
    c.add_argument("--out", type=Path, default=Path("convergence.png"), help="PNG file (default: convergence.png)")
    c.add_argument("--smooth", type=int_in(1, MAX_SMOOTH), default=1, metavar="N",
                   help=f"moving mean over N episodes (1 to {MAX_SMOOTH:,}; default: 1, none)")
    c.set_defaults(func=_convergence)
    h = psub.add_parser(
        "heatmap",
        help="difficulty (x) vs coverage (y) of a map's garages, count per 0.1 cell",
        description="Counts the library's garages of one map in 0.1 x 0.1 cells of difficulty and coverage: "
        "the paper's difficulty (--metric paper, the paper's figure) or the route difficulty (--metric route, "
        "as stored by 'garage-mj library rate'; garages without a feasible stall have none and are left out).",
    )
    h.add_argument("--library", type=Path, required=True, help="library file (library.sqlite)")
    h.add_argument("--map", required=True, help="map name as stored (see 'garage-mj library stats')")
    h.add_argument("--out", type=Path, help="PNG file (default: heatmap_MAP.png, heatmap_route_MAP.png)")
    h.add_argument("--metric", choices=("paper", "route"), default="paper",
                   help="the difficulty on x: the paper's (default) or the route difficulty")
    h.add_argument("--route-model", type=Path, metavar="FILE",
                   help=f"with --metric route: the model the values were rated with (default: the shipped one; {SHIPPED_ROUTE_MODELS})")
    h.set_defaults(func=_heatmap)
    d = psub.add_parser(
        "driver",
        help="a learned driver's training curve: validation success and agreement with the oracle per iteration",
        description="Reads curve.csv of each run folder written by 'garage-mj train-driver'.",
    )
    d.add_argument("runs", nargs="+", type=Path, metavar="RUN", help="train-driver run folders (or their curve.csv)")
    d.add_argument("--out", type=Path, default=Path("driver_curve.png"), help="PNG file (default: driver_curve.png)")
    d.set_defaults(func=_driver)


@user_errors
def _convergence(args: argparse.Namespace) -> int:
    from garage_mj.reporting.plots import convergence

    out = convergence(args.runs, args.out, smooth=args.smooth)
    print(f"convergence of {len(args.runs)} run(s) -> {out}")
    return 0


@user_errors
def _heatmap(args: argparse.Namespace) -> int:
    from garage_mj.reporting.plots import heatmap

    key = route_key(args) if args.metric == "route" else None
    with Library(args.library, create=False) as lib:
        maps = lib.maps()
        if args.map not in maps:
            raise UserError(f"{args.library} has no garage of map {args.map!r}; maps in it: {', '.join(maps) or 'none'}")
        points = lib.points(args.map, route_model=key)
    if len(points) == 0:
        raise UserError(f"no garage of map {args.map!r} in {args.library} has a route difficulty (none has a feasible "
                        "stall); plot the paper's difficulty (--metric paper)")
    default = f"heatmap_route_{args.map}.png" if key else f"heatmap_{args.map}.png"
    out = heatmap(points, args.out or Path(default), title=args.map, metric=args.metric)
    what = f"route difficulty (model {key})" if key else "difficulty"
    print(f"heatmap of {len(points)} garage(s) of {args.map}, {what} x coverage -> {out}")
    return 0


@user_errors
def _driver(args: argparse.Namespace) -> int:
    from garage_mj.reporting.plots import driver_curve

    out = driver_curve(args.runs, args.out)
    print(f"training curve of {len(args.runs)} run(s) -> {out}")
    return 0
