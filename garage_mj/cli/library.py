"""``garage-mj library ls|show|stats|sample|export-json|rate``: browse the scenario library, rate its route difficulty."""

from __future__ import annotations

import argparse
import json
import math
import sys
from pathlib import Path

from garage_mj.cli import UserError
from garage_mj.cli._common import (
    MAX_ROWS,
    MAX_WORKERS,
    SHIPPED_ROUTE_MODELS,
    add_filters,
    compute,
    filters,
    int_in,
    refuse_overwriting,
    route_key,
    seed,
    user_errors,
)
from garage_mj.core.fsutil import atomic_write, write_error
from garage_mj.driving.difficulty.rating import rate_library
from garage_mj.generation.library import Library
from garage_mj.grid.text import draw

HEADER = (f"{'id':>6}  {'map':<18} {'seed':>4} {'episode':>7} {'timestep':>9}  {'diff':>5} {'route':>5} {'cov':>5} "
          f"{'stalls':>6} {'E[X]':>5} {'E[Y]':>5}")
ROUTE_NOTE = ("diff: the paper's difficulty; route: the route difficulty (expected failure rate) under model {key}, "
              "'-' not rated yet (garage-mj library rate), 'n/a' no feasible stall")
#: The same for a park key (``park:<model>:<geometry>``, stored by ``generate --metric park``).
PARK_NOTE = ("diff: the paper's difficulty; route: the park difficulty (expected failure rate of its park tests) under "
             "{key}, '-' not rated under it")


def register(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser(
        "library",
        help="browse the scenario library (list, show, stats, sample, export)",
        description="Browse a scenario library written by 'garage-mj train' (library.sqlite). "
        "Filters: --map NAME, --difficulty LO HI, --coverage LO HI, --route-difficulty LO HI (inclusive), --limit N.",
    )
    lsub = p.add_subparsers(dest="library_command", metavar="ACTION", required=True)
    ls = lsub.add_parser("ls", help="one line per garage: id, provenance, metrics")
    ls.add_argument("library", type=Path, metavar="LIBRARY", help="library file (library.sqlite)")
    add_filters(ls)
    ls.set_defaults(func=_ls)
    show = lsub.add_parser("show", help="draw one garage as text with its metrics and provenance")
    show.add_argument("library", type=Path, metavar="LIBRARY", help="library file (library.sqlite)")
    show.add_argument("id", type=int, help="garage id (see 'library ls')")
    show.add_argument("--route-model", type=Path, metavar="FILE", help=ROUTE_MODEL_HELP)
    show.set_defaults(func=_show)
    stats = lsub.add_parser("stats", help="garages per map and the range of their metrics")
    stats.add_argument("library", type=Path, metavar="LIBRARY", help="library file (library.sqlite)")
    stats.add_argument("--json", action="store_true", help="print JSON instead of text")
    stats.add_argument("--route-model", type=Path, metavar="FILE", help=ROUTE_MODEL_HELP)
    stats.set_defaults(func=_stats)
    sample = lsub.add_parser("sample", help="a seeded sample, spread evenly over difficulty")
    sample.add_argument("library", type=Path, metavar="LIBRARY", help="library file (library.sqlite)")
    sample.add_argument("-n", type=int_in(0, MAX_ROWS), required=True, help=f"garages to draw (0 to {MAX_ROWS:,})")
    sample.add_argument("--seed", type=seed, default=0, help="random seed (default: 0)")
    sample.add_argument("--uniform", action="store_true", help="draw uniformly, not stratified by difficulty")
    add_filters(sample)
    sample.set_defaults(func=_sample)
    ex = lsub.add_parser("export-json", help="garages with grids and metrics as a JSON list")
    ex.add_argument("library", type=Path, metavar="LIBRARY", help="library file (library.sqlite)")
    ex.add_argument("--out", type=Path, help="output file (default: standard output)")
    add_filters(ex)
    ex.set_defaults(func=_export)
    rate = lsub.add_parser(
        "rate", help="compute and store the route difficulty of every garage not rated yet (resumable)",
        description="Compute the route difficulty (garage-mj difficulty) of every garage of LIBRARY without one under "
                    "the model and store each value as it is computed: a killed rating loses nothing, a re-run rates "
                    "the rest. The values do not depend on --workers. 'library ls/sample/export-json "
                    "--route-difficulty LO HI' filter on them.")
    rate.add_argument("library", type=Path, metavar="LIBRARY", help="library file (library.sqlite)")
    rate.add_argument("--map", help="only garages of this map (name as stored)")
    rate.add_argument("--model", "--route-model", dest="route_model", type=Path, metavar="FILE",
                      help=f"route difficulty model (default: the shipped one; {SHIPPED_ROUTE_MODELS}; 'garage-mj difficulty fit' writes others)")
    rate.add_argument("--workers", type=int_in(1, MAX_WORKERS), default=1,
                      help=f"worker processes, 1 to {MAX_WORKERS:,} (default 1)")
    rate.add_argument("--limit", type=int_in(0, MAX_ROWS),
                      help=f"rate at most N garages (0 to {MAX_ROWS:,}; the rest on a later call)")
    rate.add_argument("--quiet", action="store_true", help="no progress bar")
    rate.set_defaults(func=_rate)


ROUTE_MODEL_HELP = f"route difficulty model of the values shown (default: the shipped one; {SHIPPED_ROUTE_MODELS})"


def _open(path: Path):
    return Library(path, create=False)


def fmt_route(value: float | None) -> str:
    """A stored route difficulty as the commands print it: 3 decimals, ``-`` not rated, ``n/a`` no feasible stall."""
    return "-" if value is None else "n/a" if math.isnan(value) else f"{value:.3f}"


def _line(r, route: float | None) -> str:
    return (f"{r.id:>6}  {r.map:<18} {r.seed:>4} {r.episode:>7} {r.timestep:>9}  {r.difficulty:5.3f} "
            f"{fmt_route(route):>5} {r.coverage:5.3f} {r.stalls:>6} {r.mean_road_length:5.2f} "
            f"{r.mean_intersection_degree:5.2f}")


def _print_records(records, route: dict[int, float], key: str) -> None:
    print(HEADER)
    for r in records:
        print(_line(r, route.get(r.id)))
    print(f"{len(records)} garage(s); " + (PARK_NOTE if key.startswith("park:") else ROUTE_NOTE).format(key=key))


@user_errors
def _ls(args: argparse.Namespace) -> int:
    key = route_key(args)
    with _open(args.library) as lib:
        records = lib.query(**filters(args), limit=args.limit)
        _print_records(records, lib.route_difficulties([r.id for r in records], key), key)
    return 0


@user_errors
def _show(args: argparse.Namespace) -> int:
    key = route_key(args)
    with _open(args.library) as lib:
        r = lib.get(args.id)
        route = lib.route_difficulties([r.id], key).get(r.id)
    print(f"garage {r.id}: map {r.map}, run {r.run}, seed {r.seed}, episode {r.episode}, timestep {r.timestep}")
    print(f"difficulty {r.difficulty:.3f} (the paper's)  route difficulty {fmt_route(route)} (model {key})  "
          f"coverage {r.coverage:.3f}  stalls {r.stalls}  "
          f"E[X] {r.mean_road_length:.3f}  E[Y] {r.mean_intersection_degree:.3f}  six-stall axis {r.six_stall_axis}")
    print(draw(r.garage.grid, legend=True))
    return 0


@user_errors
def _stats(args: argparse.Namespace) -> int:
    key = route_key(args)
    with _open(args.library) as lib:
        s = lib.stats(route_model=key)
    if args.json:
        print(json.dumps(s, indent=2))
        return 0
    print(f"{s['path']}: {s['total']} garage(s), schema version {s['schema_version']}")
    for name, m in s["maps"].items():
        d, c = m["difficulty"], m["coverage"]
        rd = m.get("route_difficulty")
        route = "route difficulty not rated"
        if rd is not None:
            span = (f"{rd['min']:.3f}-{rd['max']:.3f} (mean {rd['mean']:.3f})" if rd["with_value"]
                    else "n/a (no feasible stall)")
            route = f"route difficulty {span} over {rd['rated']} rated"
        print(f"  {name:<18} {m['garages']:>6} garages from {m['runs']} run(s)  "
              f"difficulty {d['min']:.3f}-{d['max']:.3f} (mean {d['mean']:.3f})  {route}  "
              f"coverage {c['min']:.3f}-{c['max']:.3f} (mean {c['mean']:.3f})  stalls max {m['stalls']['max']}")
    print(f"difficulty: the paper's; route difficulty: model {key} (garage-mj library rate)")
    return 0


@user_errors
def _sample(args: argparse.Namespace) -> int:
    f = filters(args)
    key = route_key(args)
    with _open(args.library) as lib:
        records = lib.sample(args.n, args.seed, stratify=None if args.uniform else "difficulty", **f)
        records = records[: args.limit] if args.limit is not None else records
        _print_records(records, lib.route_difficulties([r.id for r in records], key), key)
    return 0


@user_errors
def _export(args: argparse.Namespace) -> int:
    key = route_key(args)
    if args.out is not None:
        refuse_overwriting(args.out, "--out", [args.library])
    with _open(args.library) as lib:
        records = lib.query(**filters(args), limit=args.limit)
        route = lib.route_difficulties([r.id for r in records], key)
    # route_difficulty: null when not rated under the model or rated without a feasible stall
    rows = [{**r.to_dict(), "route_difficulty": None if math.isnan(route.get(r.id, math.nan)) else route[r.id],
             "route_model": key} for r in records]
    text = json.dumps(rows, indent=1) + "\n"
    if args.out is None:
        sys.stdout.write(text)
        return 0
    try:
        args.out.parent.mkdir(parents=True, exist_ok=True)
        atomic_write(args.out, text)
    except OSError as exc:
        raise write_error(args.out, exc) from None
    print(f"{len(records)} garage(s) -> {args.out}", file=sys.stderr)
    return 0


@user_errors
def _rate(args: argparse.Namespace) -> int:
    with _open(args.library) as lib:  # a missing or foreign file: one line, before any worker starts
        maps = lib.maps()
    if args.map is not None and args.map not in maps:
        raise UserError(f"{args.library} has no garage of map {args.map!r}; maps in it: {', '.join(maps) or 'none'}")
    res = rate_library(args.library, args.route_model, map=args.map, limit=args.limit, compute=compute(args))
    per = "" if res.seconds_per_garage is None else (
        f" in {res.seconds:.1f} s ({res.seconds_per_garage:.2f} s per garage, {res.workers} worker(s))")
    left = f"; {res.left} left (run it again)" if res.left else ""
    print(f"rated {res.rated} garage(s) under route difficulty model {res.model_key}{per}{left}; "
          f"stored in {args.library}")
    return 0
