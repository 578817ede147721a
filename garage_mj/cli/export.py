"""``garage-mj export``: asset packs (OpenDRIVE, MJCF, GLB/OBJ/FBX, preview) and CARLA import packages.

``--garage garage.json`` exports one garage (or each of a ``library export-json`` list); ``--library FILE``
exports the library's garages that pass the filters, or those of ``--ids``. Packs land in ``--out DIR`` (one folder each, plus ``index.json``);
complete packs are skipped, partial ones repaired. ``--carla-package DIR`` (with or without
``--out``) adds the same garages to a package for CARLA's ``make import``
(:mod:`garage_mj.export.carla_package`), whose lock it holds for the whole export; maps
already in the package stay, complete ones are not rebuilt. ``--park-problems DIR`` writes every park test
of the garages as a planning problem, JSON and a TPCAP case each (:mod:`garage_mj.export.park_problems`).
Without Assimp (no wheel for the platform) packs are written without ``garage.fbx`` and one line says so; a
CARLA package is refused. The park geometry options (``--stall-width``, ``--stall-depth``, ``--aisle-width``,
``--stall-angle``, ``--slot-length``, ``--layout FILE.toml``; docs/spec.md section 9) build every pack and park
problem in that geometry; a geometry a garage cannot hold is refused before anything is written.
"""

from __future__ import annotations

import argparse
import json
import sys
from contextlib import ExitStack
from pathlib import Path

from garage_mj.cli import UserError
from garage_mj.cli._common import add_geometry_args, add_ids, geometry_world, non_negative_int, records_by_id
from garage_mj.export.artefacts import INDEX, contents, formats, left_out_here
from garage_mj.generation.library import Library, LibraryError, garages_from_json
from garage_mj.grid.garage import Garage
from garage_mj.scene.vehicles import DEFAULT_VEHICLE, FLEET, vehicle_class


def register(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser(
        "export",
        help=f"export garages as asset packs ({formats()}), CARLA import packages and park planning problems",
        description=f"Write one asset pack folder per garage under --out, plus {INDEX}. Re-running skips\n"
        "complete packs and repairs partial ones. --carla-package DIR adds the garages to a package\n"
        "for CARLA's map import (maps already in it stay): copy DIR into CARLA's Import/ folder and\n"
        "run `make import`. --park-problems DIR writes every park test as a planning problem (start\n"
        "pose, stall pose, obstacle polygons) in JSON and in the TPCAP benchmark's case layout.",
        epilog=f"Each asset pack holds:\n{contents()}",
        formatter_class=argparse.RawDescriptionHelpFormatter,
    )
    src = p.add_mutually_exclusive_group(required=True)
    src.add_argument("--garage", type=Path, metavar="FILE",
                     help="a garage JSON file (Garage.to_json), or the list of garages 'garage-mj library export-json' "
                          "writes")
    src.add_argument("--library", type=Path, metavar="FILE", help="a scenario library (library.sqlite)")
    p.add_argument("--map", help="library filter: map name")
    p.add_argument("--difficulty", type=float, nargs=2, metavar=("LO", "HI"), help="library filter, inclusive")
    p.add_argument("--coverage", type=float, nargs=2, metavar=("LO", "HI"), help="library filter, inclusive")
    p.add_argument("--feasible", type=float, nargs=2, metavar=("LO", "HI"),
                   help="library filter: share of stalls with a feasible cruise test (garage-mj check --store)")
    p.add_argument("--limit", type=int, help="library filter: at most N garages")
    add_ids(p)
    p.add_argument("--out", type=Path, metavar="DIR", help="folder for the asset packs")
    p.add_argument("--carla-package", type=Path, metavar="DIR",
                   help="also (or only) add the garages to a CARLA import package here: DIR/DIR.json and one "
                   "<map>.fbx + <map>.xodr folder per garage (maps already in DIR stay); the folder's name is "
                   "the package name")
    p.add_argument("--park-problems", type=Path, metavar="DIR",
                   help="also (or only) write every park test (each stall with a feasible cruise test, reverse-in "
                   "and nose-in) as a planning problem: start pose, stall pose and obstacle polygons, as JSON and "
                   "as a TPCAP benchmark case (CSV), one folder per garage, index DIR/park_problems.json")
    p.add_argument("--vehicle", choices=tuple(FLEET), default=DEFAULT_VEHICLE,
                   help=f"with --park-problems: the car the problems are for, a class of the fleet (default "
                        f"{DEFAULT_VEHICLE}: models/car); its outline, axles and turning radius shape every problem")
    p.add_argument("--stall", type=non_negative_int, action="append", metavar="ID",
                   help="with --park-problems: only this stall's problems (repeat for more; default every stall); "
                        "an id a garage lacks is refused before anything is written, naming its range")
    p.add_argument("--maneuver", choices=("reverse", "forward", "both"), default="both",
                   help="with --park-problems: reverse-in, forward (nose-in) or both problems per stall (default)")
    add_geometry_args(p)
    p.add_argument("--force", action="store_true", help="rebuild packs and CARLA maps that are already complete")
    p.add_argument("--quiet", action="store_true", help="no progress bar")
    p.set_defaults(func=run)


def _from_library(args: argparse.Namespace) -> list:
    try:
        lib = Library(args.library, create=False)
    except LibraryError as exc:
        raise UserError(str(exc)) from None
    with lib:
        if args.ids is not None:
            return [r.garage for r in records_by_id(lib, args)]
        try:
            records = lib.query(
                map=args.map,
                difficulty=tuple(args.difficulty) if args.difficulty else None,
                coverage=tuple(args.coverage) if args.coverage else None,
                feasible=tuple(args.feasible) if args.feasible else None,
                limit=args.limit,
            )
        except ValueError as exc:
            raise UserError(str(exc)) from None
        if not records:
            raise UserError(f"no garage in {args.library} matches the filters; widen them or check --map")
        records = lib.verified(records)  # hash and metrics recomputed: an altered row is refused by id
    return [r.garage for r in records]


def run(args: argparse.Namespace) -> int:
    world = geometry_world(args)  # a bad geometry is refused before anything else
    if args.out is None and args.carla_package is None and args.park_problems is None:
        raise UserError("give --out DIR (asset packs), --carla-package DIR (a CARLA import package), or both"
                        " (or --park-problems DIR)")
    if args.vehicle != DEFAULT_VEHICLE and args.park_problems is None:
        raise UserError(f"--vehicle {args.vehicle} chooses the car of --park-problems (packs hold no car); give "
                        "--park-problems DIR or leave --vehicle out")
    if (args.stall is not None or args.maneuver != "both") and args.park_problems is None:
        raise UserError("--stall and --maneuver choose which --park-problems to write (packs hold every stall); "
                        "give --park-problems DIR or leave them out")
    if args.out is not None and args.carla_package is not None and \
            args.out.resolve() == args.carla_package.resolve():
        raise UserError(f"--out and --carla-package both name {args.out}; give the package a folder of its own")
    if args.park_problems is not None:
        for flag, other in (("--out", args.out), ("--carla-package", args.carla_package)):
            if other is not None and other.resolve() == args.park_problems.resolve():
                raise UserError(f"{flag} and --park-problems both name {other}; give the park problems a folder of "
                                "their own")
    with ExitStack() as stack:
        if args.carla_package is not None:
            from garage_mj.export.carla_package import package_lock

            # a bad or busy folder is refused before any work; the lock is held to the end
            stack.enter_context(package_lock(args.carla_package))
        if args.park_problems is not None:
            from garage_mj.export.park_problems import check_park_problems_targets, park_problems_lock

            stack.enter_context(park_problems_lock(args.park_problems))  # the same, for the park problems' folder
        garages = _garages(args)
        if not world.is_default_geometry:
            from garage_mj.export.pack import check_geometry

            if args.carla_package is not None:
                raise UserError("--carla-package writes the default park geometry only; leave out the geometry "
                                "options, or export packs with --out")
            check_geometry(garages, world)  # every garage holds it, or one line names the block and the fix
        args.world = world
        if args.park_problems is not None:
            from garage_mj.export.park_problems import check_problem_choice
            from garage_mj.scene.garage_scene import GarageScene

            scenes = [GarageScene(g, world) for g in garages]
            # a stall id a garage lacks, or a read-only folder: refused before any pack
            check_problem_choice(scenes, _stalls(args), _maneuvers(args))
            check_park_problems_targets(scenes, args.park_problems)
        _export(args, garages)
    return 0


def _garages(args: argparse.Namespace) -> list[Garage]:
    """The garages to export: the ``--garage`` file (one garage or a ``library export-json`` list), or the
    ``--library`` rows that pass the filters or have the ``--ids``."""
    if args.library is not None:
        return _from_library(args)
    if any(v is not None for v in (args.map, args.difficulty, args.coverage, args.feasible, args.limit, args.ids)):
        raise UserError("--map, --difficulty, --coverage, --feasible, --limit and --ids pick garages of a --library, "
                        "not of a --garage file")
    try:
        text = args.garage.read_bytes()
    except OSError as exc:
        raise UserError(f"cannot read {args.garage}: {exc.strerror}") from None
    return garages_from_json(text, source=str(args.garage))


def _export(args: argparse.Namespace, garages: list[Garage]) -> None:
    """Write the packs and/or the CARLA package (whose lock the caller holds)."""
    if args.out is not None:
        from garage_mj.export.pack import export_packs

        for name, problem in left_out_here().items():
            print(f"{name} left out of the packs: {problem}", file=sys.stderr)
        paths = export_packs(garages, args.out, force=args.force, progress=not args.quiet, total=len(garages),
                             world=args.world)
        for path in paths:
            print(path)
        print(f"{len(paths)} pack(s) in {args.out} (index: {args.out / INDEX})")
    if args.carla_package is not None:
        from garage_mj.export.carla_package import write_carla_package

        description = write_carla_package(garages, args.carla_package, force=args.force, locked=True)
        count = len(json.loads(description.read_text())["maps"])
        print(f"CARLA package {description.parent.name}: {count} map(s) in {args.carla_package}; copy the folder "
              "into CARLA's Import/ folder and run `make import`")
    if args.park_problems is not None:
        from garage_mj.export.park_problems import write_park_problems
        from garage_mj.scene.garage_scene import GarageScene

        car = None if args.vehicle == DEFAULT_VEHICLE else vehicle_class(args.vehicle).geometry()
        index = write_park_problems([GarageScene(g, args.world) for g in garages], args.park_problems, car,
                                    stalls=_stalls(args), maneuvers=_maneuvers(args), locked=True)
        count = len(json.loads(index.read_text())["problems"])
        print(f"{count} park problem(s) of {len(garages)} garage(s) in {args.park_problems} (index: {index})")


def _stalls(args: argparse.Namespace) -> frozenset[int] | None:
    """``--stall``: the stalls whose park problems to write, or None for every stall."""
    return None if args.stall is None else frozenset(args.stall)


def _maneuvers(args: argparse.Namespace) -> tuple[str, ...]:
    """``--maneuver``: the maneuvers of the park problems to write."""
    from garage_mj.scene.park_planning import MANEUVERS

    return tuple(MANEUVERS) if args.maneuver == "both" else (args.maneuver,)
