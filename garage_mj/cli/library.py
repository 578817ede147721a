"""``garage-mj library ls|show|stats|sample|export-json``: browse the scenario library."""

from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path

from garage_mj.cli._common import add_filters, filters, non_negative_int, seed, user_errors
from garage_mj.core.fsutil import atomic_write, write_error
from garage_mj.generation.library import Library
from garage_mj.grid.text import draw

HEADER = f"{'id':>6}  {'map':<18} {'seed':>4} {'episode':>7} {'timestep':>9}  {'diff':>5} {'cov':>5} {'stalls':>6} {'E[X]':>5} {'E[Y]':>5}"


def register(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser(
        "library",
        help="browse the scenario library (list, show, stats, sample, export)",
        description="Browse a scenario library written by 'garage-mj train' (library.sqlite). "
        "Filters: --map NAME, --difficulty LO HI, --coverage LO HI (inclusive), --limit N.",
    )
    lsub = p.add_subparsers(dest="library_command", metavar="ACTION", required=True)
    ls = lsub.add_parser("ls", help="one line per garage: id, provenance, metrics")
    ls.add_argument("library", type=Path, metavar="LIBRARY", help="library file (library.sqlite)")
    add_filters(ls)
    ls.set_defaults(func=_ls)
    show = lsub.add_parser("show", help="draw one garage as text with its metrics and provenance")
    show.add_argument("library", type=Path, metavar="LIBRARY", help="library file (library.sqlite)")
    show.add_argument("id", type=int, help="garage id (see 'library ls')")
    show.set_defaults(func=_show)
    stats = lsub.add_parser("stats", help="garages per map and the range of their metrics")
    stats.add_argument("library", type=Path, metavar="LIBRARY", help="library file (library.sqlite)")
    stats.add_argument("--json", action="store_true", help="print JSON instead of text")
    stats.set_defaults(func=_stats)
    sample = lsub.add_parser("sample", help="a seeded sample, spread evenly over difficulty")
    sample.add_argument("library", type=Path, metavar="LIBRARY", help="library file (library.sqlite)")
    sample.add_argument("-n", type=non_negative_int, required=True, help="garages to draw")
    sample.add_argument("--seed", type=seed, default=0, help="random seed (default: 0)")
    sample.add_argument("--uniform", action="store_true", help="draw uniformly, not stratified by difficulty")
    add_filters(sample)
    sample.set_defaults(func=_sample)
    ex = lsub.add_parser("export-json", help="garages with grids and metrics as a JSON list")
    ex.add_argument("library", type=Path, metavar="LIBRARY", help="library file (library.sqlite)")
    ex.add_argument("--out", type=Path, help="output file (default: standard output)")
    add_filters(ex)
    ex.set_defaults(func=_export)


def _open(path: Path):
    return Library(path, create=False)


def _line(r) -> str:
    return (f"{r.id:>6}  {r.map:<18} {r.seed:>4} {r.episode:>7} {r.timestep:>9}  {r.difficulty:5.3f} "
            f"{r.coverage:5.3f} {r.stalls:>6} {r.mean_road_length:5.2f} {r.mean_intersection_degree:5.2f}")


def _print_records(records) -> None:
    print(HEADER)
    for r in records:
        print(_line(r))
    print(f"{len(records)} garage(s)")


@user_errors
def _ls(args: argparse.Namespace) -> int:
    with _open(args.library) as lib:
        _print_records(lib.query(**filters(args), limit=args.limit))
    return 0


@user_errors
def _show(args: argparse.Namespace) -> int:
    with _open(args.library) as lib:
        r = lib.get(args.id)
    print(f"garage {r.id}: map {r.map}, run {r.run}, seed {r.seed}, episode {r.episode}, timestep {r.timestep}")
    print(f"difficulty {r.difficulty:.3f}  coverage {r.coverage:.3f}  stalls {r.stalls}  "
          f"E[X] {r.mean_road_length:.3f}  E[Y] {r.mean_intersection_degree:.3f}  six-stall axis {r.six_stall_axis}")
    print(draw(r.garage.grid, legend=True))
    return 0


@user_errors
def _stats(args: argparse.Namespace) -> int:
    with _open(args.library) as lib:
        s = lib.stats()
    if args.json:
        print(json.dumps(s, indent=2))
        return 0
    print(f"{s['path']}: {s['total']} garage(s), schema version {s['schema_version']}")
    for name, m in s["maps"].items():
        d, c = m["difficulty"], m["coverage"]
        print(f"  {name:<18} {m['garages']:>6} garages from {m['runs']} run(s)  "
              f"difficulty {d['min']:.3f}-{d['max']:.3f} (mean {d['mean']:.3f})  "
              f"coverage {c['min']:.3f}-{c['max']:.3f} (mean {c['mean']:.3f})  stalls max {m['stalls']['max']}")
    return 0


@user_errors
def _sample(args: argparse.Namespace) -> int:
    f = filters(args)
    with _open(args.library) as lib:
        records = lib.sample(args.n, args.seed, stratify=None if args.uniform else "difficulty", **f)
    _print_records(records[: args.limit] if args.limit is not None else records)
    return 0


@user_errors
def _export(args: argparse.Namespace) -> int:
    with _open(args.library) as lib:
        records = lib.query(**filters(args), limit=args.limit)
    text = json.dumps([r.to_dict() for r in records], indent=1) + "\n"
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
