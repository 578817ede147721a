"""``garage-mj check``: can the car drive this garage? Per garage, before any cruise test.

For asset packs (``PACK...``) or a scenario library (``--library FILE`` with filters), prints
one line per garage: the share of stalls whose cruise test is feasible for the configured car
(a forward route the car can steer, its swept footprint clear of walls, pillars, obstacles and
parked cars, the goal on the lane beside the stall), the smallest clearance, the largest route
curvature against the car's limit, and the commonest reason a stall is infeasible. ``--json``
writes every figure; ``--stalls`` lists each stall.
"""

from __future__ import annotations

import argparse
import json
from pathlib import Path

from garage_mj.cli import UserError
from garage_mj.cli._common import MAX_ROWS, check_output_file, checked_range, int_in, unit_range
from garage_mj.core.fsutil import atomic_write
from garage_mj.generation.library import Library


def register(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser(
        "check",
        help="drivability of garages: feasible stalls, clearance, curvature vs the car's limit",
        description=__doc__.split("\n\n", 1)[1],
        formatter_class=argparse.RawDescriptionHelpFormatter,
    )
    p.add_argument("packs", nargs="*", type=Path, metavar="PACK", help="asset pack folders (garage-mj export)")
    p.add_argument("--library", type=Path, metavar="FILE", help="check a scenario library's garages instead")
    p.add_argument("--map", help="library filter: map name")
    p.add_argument("--difficulty", type=unit_range, nargs=2, metavar=("LO", "HI"),
                   help="library filter, inclusive (0-1)")
    p.add_argument("--limit", type=int_in(0, MAX_ROWS), help=f"library filter: at most N garages (0 to {MAX_ROWS:,})")
    p.add_argument("--max-steer", type=float, metavar="RAD",
                   help="the car's full-lock road-wheel angle [rad] (default: CarConfig, 0.7)")
    p.add_argument("--store", action="store_true",
                   help="with --library: store the figures in the library, so 'library ls/sample --feasible', "
                   "'export --feasible' and 'cruise --feasible' can filter on them")
    p.add_argument("--stalls", action="store_true", help="also print one line per stall")
    p.add_argument("--json", type=Path, metavar="FILE", help="write every figure to this JSON file")
    p.set_defaults(func=run)


def _garages(args: argparse.Namespace) -> list[tuple[str, object, object]]:
    """(name, garage or scene, library id or None) of each garage to check: a pack's scene is built in its geometry."""
    if args.library is not None:
        if args.packs:
            raise UserError("give pack folders or --library, not both")

        with Library(args.library, create=False) as lib:
            records = lib.query(map=args.map, difficulty=checked_range(args.difficulty, "difficulty"),
                                limit=args.limit)
            if not records:
                raise UserError(f"no garage in {args.library} matches the filters; widen them or check --map")
            records = lib.verified(records)
        return [(f"{r.map}#{r.id}", r.garage, r.id) for r in records]
    if not args.packs:
        raise UserError("name pack folders to check, or --library FILE")
    if any(v is not None for v in (args.map, args.difficulty, args.limit)):
        raise UserError("--map, --difficulty and --limit filter a --library, not pack folders")
    from garage_mj.export.pack import load_pack
    from garage_mj.scene.garage_scene import GarageScene

    packs = [load_pack(p) for p in args.packs]
    return [(Path(p.path).name, GarageScene(p.garage, p.world), None) for p in packs]  # in the geometry it was built in


def run(args: argparse.Namespace) -> int:
    from garage_mj.scene.car import CarConfig, car_geometry
    from garage_mj.scene.drivable import drivability, drive_planner
    from garage_mj.scene.garage_scene import as_scene

    if args.max_steer is not None and not 0.05 <= args.max_steer <= 1.2:
        raise UserError(f"--max-steer {args.max_steer} rad is not a plausible full-lock angle; use 0.05 to 1.2")
    car = car_geometry(CarConfig(max_steer=args.max_steer) if args.max_steer is not None else None)
    report = []
    if args.store and args.library is None:
        raise UserError("--store writes into a library: give --library FILE")
    if args.json is not None:
        check_output_file(args.json, "--json", [args.library])  # before any figure is stored (--store) or computed
    found = _garages(args)
    store = None
    if args.store:
        store = Library(args.library, create=False, readonly=False)
    print(f"{'garage':32s} {'feasible':>12s} {'clearance':>10s} {'curvature/limit':>16s}  commonest reason")
    car_key = f"models/car max_steer={car.max_steer:g}"
    for name, garage, lib_id in found:
        scene = as_scene(garage)
        d = drivability(scene, car)
        reasons = sorted(d["infeasible_reasons"].items(), key=lambda kv: -kv[1])
        why = f"{reasons[0][0]} ({reasons[0][1]})" if reasons else "-"
        clear = _metres(d["min_clearance"])
        curv = "-" if d["max_curvature"] is None else f"{d['max_curvature']:.3f}/{d['car_curvature_limit']:.3f}"
        print(f"{name[:32]:32s} {d['feasible_stalls']:>4d}/{d['stalls']:<4d}{100 * d['feasible_share']:3.0f}% "
              f"{clear:>10s} {curv:>16s}  {why}")
        entry = {"garage": name, **d}
        if store is not None:
            store.set_drivability(lib_id, d, car_key)
        if args.stalls or args.json:
            plans = [p.summary() for p in drive_planner(scene, car).plans()]
            entry["stall_plans"] = plans
            if args.stalls:
                for p in plans:
                    state = "feasible" if p["feasible"] else f"INFEASIBLE: {p['reason']}"
                    print(f"    stall {p['stall']:3d} {p['stall_side'] or '-':6s} route {p['route_length'] or 0:6.1f} m  "
                          f"clearance {_metres(p['clearance'])}  {state}")
        report.append(entry)
    if store is not None:
        store.close()
        print(f"stored the drivability of {len(report)} garage(s) in {args.library}")
    if args.json:
        atomic_write(args.json, json.dumps(report, indent=2) + "\n")
        print(f"wrote {args.json}")
    return 0


def _metres(value: float | None) -> str:
    """A clearance for people: '0.93 m', or '-' when there is none (no route)."""
    return "-" if value is None else f"{value:.2f} m"
