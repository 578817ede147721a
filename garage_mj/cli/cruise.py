"""``garage-mj cruise``: batch cruise tests of a driver over packs or library garages (docs/spec.md section 7);
with ``--task park`` or ``--task avp`` the park and AVP tests of section 8."""

from __future__ import annotations

import argparse
import contextlib
import csv
import io
import json
import sys
import warnings
from collections.abc import Iterator
from pathlib import Path

from garage_mj.cli import UserError
from garage_mj.cli._common import (
    add_filters,
    add_geometry_args,
    add_ids,
    compute,
    filters,
    geometry_world,
    int_in,
    non_negative_int,
    positive_int,
    positive_seconds,
    records_by_id,
    seed,
    unit_range,
    user_errors,
)
from garage_mj.core.fsutil import atomic_write, ensure_dir
from garage_mj.driving.actors.config import SCENARIOS, load_scenario_config
from garage_mj.driving.difficulty.regression import r_text
from garage_mj.driving.replay import replay_xosc
from garage_mj.driving.results import BREAKDOWNS, TEST_COLUMNS, breakdown_lines
from garage_mj.driving.sim.outcomes import RUNNER_KINDS
from garage_mj.driving.sim.park_task import MANEUVER_CHOICES, TASKS
from garage_mj.driving.sources import (
    DEFAULT_TEST_TIMEOUT,
    MAX_TEST_TIMEOUT,
    MAX_TESTS,
    CruiseSettings,
    CruiseSource,
)
from garage_mj.export.artefacts import MANIFEST
from garage_mj.generation.library import Library, LibraryError
from garage_mj.reporting.report import PICTURE_CHOICES, count_noun, task_noun
from garage_mj.scene.park_difficulty import SHIPPED_PARK_MODELS
from garage_mj.scene.world import geometry


def register(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser(
        "cruise", help="run cruise tests of a driver in garages and correlate success with difficulty",
        description="Run --tests cruise tests per garage with --driver in GarageDrive-v0 over a process "
                    "pool. Writes tests.csv (appended as tests end; a re-run resumes), summary.csv (per garage, "
                    "the paper's difficulty and the route difficulty under --route-model beside the outcomes; without it the "
                    "driver's shipped model: 'learned' for the shipped learned driver, else the default), "
                    "summary.json (Pearson r and regression on each), regression.png and regression_route.png "
                    "into --out (a park or avp run: park_success.png, its success by level and maneuver), with --videos N MP4s of N tests into OUT/videos/, and with --report "
                    "OUT/report.html.")
    src = p.add_mutually_exclusive_group(required=True)
    src.add_argument("--packs", type=Path, metavar="DIR", help="a folder of asset packs (garage-mj export)")
    src.add_argument("--library", type=Path, metavar="FILE", help="a garage library (garage-mj train)")
    src.add_argument("--scenario-file", type=Path, nargs="+", metavar="FILE.xosc",
                     help="replay tests written with --xosc (OpenSCENARIO): same garage, parked cars, start, "
                          "actors; prints each outcome and writes replay.csv into --out")
    src.add_argument("--cases", type=Path, nargs="+", metavar="PATH",
                     help="park tests from problem files, one each: TPCAP case files (CaseN.csv) or park problems "
                          "of garage-mj export --park-problems, or folders of them (docs/cruise.md, Cases from elsewhere)")
    add_filters(p)
    add_ids(p)
    p.add_argument("--sample", type=positive_int, metavar="N",
                   help="with --library: N garages stratified by difficulty (seeded by --seed)")
    p.add_argument("--tests", type=int_in(1, MAX_TESTS), default=50,
                   help=f"tests per garage, 1 to {MAX_TESTS:,} (default 50)")
    p.add_argument("--driver", help=f"built-in driver ({built_in_drivers()}; learned: the shipped deep-RL "
                                    "model), learned:PATH (a model zip of garage-mj train-driver), module:Class (a module "
                                    "on the Python path or in the current folder) or path/to/file.py:Class (default vision; with --scenario-file: the one the file records)")
    p.add_argument("--workers", type=int_in(1, MAX_WORKERS), default=1,
                   help=f"worker processes, 1 to {MAX_WORKERS:,} (default 1)")
    p.add_argument("--backend", choices=("local", "ray"), default="local",
                   help="local: this process or a process pool (default); ray: --workers Ray actors, on a private "
                        "local Ray or the cluster at --address (pip install 'garage-mj[ray]')")
    p.add_argument("--address", metavar="HOST:PORT",
                   help="with --backend ray: a running Ray cluster (ray start --head), e.g. HOST:6379")
    p.add_argument("--seed", type=seed, default=0, help="run seed; test seeds derive from it (default 0)")
    p.add_argument("--out", type=Path, default=Path("cruise"), help="output folder (default ./cruise)")
    p.add_argument("--action-type", choices=("discrete", "continuous"), default=None,
                   help="the paper's 4 actions or [throttle, steer] (default: the driver's own; the hand-written "
                        "built-ins are made for continuous, learned for discrete, a module:Class without an "
                        "action_type attribute is taken as discrete); another one than the driver's own is "
                        "warned about")
    p.add_argument("--occupancy", type=unit_range, default=0.5, help="share of stalls with a parked car")
    p.add_argument("--test-timeout", type=test_seconds, default=DEFAULT_TEST_TIMEOUT, metavar="SECONDS",
                   help=f"wall time a test may take, at most {MAX_TEST_TIMEOUT:,.0f} s (default {DEFAULT_TEST_TIMEOUT:g} s, "
                        "far above any honest test); "
                        "a test past it is a driver_timeout (its worker is stopped) and the run goes on; stored in "
                        "run.json like the seed")
    p.add_argument("--videos", type=video_count, default=0, metavar="N",
                   help="after the tests, MP4s of N of them (failures first, then successes, in garage and test "
                        "order) into OUT/videos/<garage>_<test>_<outcome>.mp4; re-run on a finished --out to only "
                        "make videos")
    p.add_argument("--report", action="store_true",
                   help="after the tests (and videos), OUT/report.html: the success and regression figures, the "
                        "failures' reasons per class and the first failures with their files (MP4 from --videos, "
                        ".xosc from --xosc); a park or AVP run's has the park table, its success by level and "
                        "maneuver instead of the regressions, and a top-down picture of each failure shown "
                        "(OUT/pictures/; --pictures all: of every driven test)")
    p.add_argument("--pictures", choices=PICTURE_CHOICES, default=None,
                   help="park and avp: top-down pictures into OUT/pictures/ (the stalls, obstacles, plan, driven path, "
                        "final footprint, a collision's point, the line an outside_stall crosses): failures (the "
                        "failures the report shows; the default with --report) or all (every driven test, successes "
                        "too); drawn with --report or when given")
    add_actor_arguments(p.add_argument_group("adverse events (garage_mj.driving.actors.scenario; drawn per test "
                                             "from its seed)"))
    p.add_argument("--xosc", action="store_true",
                   help="also write every test as OpenSCENARIO 1.2 into OUT/xosc/ (garages without an asset "
                        "pack get one in OUT/packs/); replay one with --scenario-file")
    add_task_args(p, stall=True)
    p.add_argument("--park-model", metavar="FILE",
                   help="park and avp: the park difficulty model of tests.csv's park_difficulty column (default: the "
                        "driver's shipped one, else the one fitted on park_assist; a shipped one by name: "
                        f"{', '.join(SHIPPED_PARK_MODELS)}; 'garage-mj difficulty fit --task park' writes others)")
    add_geometry_args(p)
    add_vehicle_args(p)
    add_sensor_args(p)
    add_guide_args(p)
    p.add_argument("--quiet", action="store_true", help="no progress bar")
    p.set_defaults(func=user_errors(run))


def built_in_drivers() -> str:
    """The hand-written built-in drivers as ``--driver`` help names them (the ``DRIVERS`` table), one not made for
    cruise tests with the tasks it is: ``oracle, waypoint, vision, park_assist (park and avp tests only)``."""
    from garage_mj.driving.drivers import DRIVERS, tasks_of

    def named(name: str) -> str:
        tasks = tasks_of(name)
        return name if "cruise" in tasks else f"{name} ({' and '.join(tasks)} tests only)"

    return ", ".join(map(named, DRIVERS))


def add_vehicle_args(p: argparse.ArgumentParser) -> None:
    """``--vehicle``, ``--parked-fleet`` and ``--parked-jitter``: the cars of each test (docs/spec.md section 9)."""
    from garage_mj.scene.parked_fleet import MAX_PARKED_JITTER, PARKED_FLEETS
    from garage_mj.scene.vehicles import DEFAULT_VEHICLE, FLEET

    g = p.add_argument_group("vehicles (docs/spec.md section 9; stored in run.json and tests.csv)")
    g.add_argument("--vehicle", choices=tuple(FLEET), default=DEFAULT_VEHICLE,
                   help=f"the car under test's class (default {DEFAULT_VEHICLE}: models/car): its body, axles and "
                        "full lock in MuJoCo, the planners and the monitors")
    g.add_argument("--parked-fleet", choices=PARKED_FLEETS, default="uniform",
                   help="uniform: every parked car is models/parked_car, centred (default); mixed: each parked car's "
                        "class drawn from the fleet per test (seeded)")
    g.add_argument("--parked-jitter", type=jitter_metres, default=0.0, metavar="M",
                   help=f"each parked car's lateral offset, up to M metres (0 to {MAX_PARKED_JITTER:g}, default 0), and a "
                        "heading jitter in proportion, drawn per test; never into the target stall's paint")


def jitter_metres(text: str) -> float:
    """argparse type of --parked-jitter: metres from 0 to :data:`~garage_mj.scene.parked_fleet.MAX_PARKED_JITTER`."""
    from garage_mj.scene.parked_fleet import MAX_PARKED_JITTER

    try:
        value = float(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"{text!r} is not a number of metres") from None
    if not 0.0 <= value <= MAX_PARKED_JITTER:  # NaN fails too
        raise argparse.ArgumentTypeError(f"{text} m is outside 0 to {MAX_PARKED_JITTER:g} m")
    return value


def vehicle_env(args: argparse.Namespace) -> dict:
    """The ``GarageDriveEnv`` keyword arguments of the vehicle options, only those that differ from the defaults (so a
    default run's ``run.json`` stays as it was)."""
    from garage_mj.scene.vehicles import DEFAULT_VEHICLE

    env: dict = {}
    if args.vehicle != DEFAULT_VEHICLE:
        env["vehicle"] = args.vehicle
    if args.parked_fleet != "uniform":
        env["parked_fleet"] = args.parked_fleet
    if args.parked_jitter > 0:
        env["parked_jitter"] = args.parked_jitter
    return env


def add_sensor_args(p: argparse.ArgumentParser) -> None:
    """``--sensors`` and ``--slot-noise``: the parking sensors a driver observes (docs/observations.md)."""
    g = p.add_argument_group("parking sensors (docs/observations.md; stored in run.json)")
    g.add_argument("--sensors", type=sensor_names, metavar="NAMES",
                   help="observe these sensors too, comma-separated: rear_camera (rear_depth, rear_segmentation), "
                        "ultrasonic (12 bumper ranges), slot (the target stall in the car frame), or all; for your "
                        "own driver (module:Class): the built-in drivers do not read them (default: none)")
    g.add_argument("--slot-noise", type=float, nargs=2, metavar=("M", "RAD"),
                   help="the slot detector's noise: standard deviations of its position (each of x, y) and its yaw, "
                        "drawn per observation from the test's seed (needs --sensors with slot; default 0 0)")


def add_guide_args(p: argparse.ArgumentParser) -> None:
    """``--guide-replans``: how often the park guide may plan again (docs/observations.md, ``park_guide``)."""
    from garage_mj.driving.sim.park_guide import MAX_REPLANS

    p.add_argument("--guide-replans", type=int_in(0, 10), default=MAX_REPLANS, metavar="N",
                   help="park and avp: new plans the park guide (the observation's park_guide) may show a test, each "
                        "from where the car stands at rest outside the stall, as a park assist plans again (0 to 10, "
                        f"default {MAX_REPLANS}; 0: the test's plan only). The test is judged along its own plan")


def guide_env(args: argparse.Namespace) -> dict:
    """The ``GarageDriveEnv`` keyword argument of ``--guide-replans``, only when it differs from the default."""
    from garage_mj.driving.sim.park_guide import MAX_REPLANS

    return {} if args.guide_replans == MAX_REPLANS else {"guide_replans": args.guide_replans}


def sensor_names(text: str) -> list[str]:
    """argparse type of --sensors: sensor names (:func:`~garage_mj.driving.sim.park_sensors.sensor_config` reads them)."""
    from garage_mj.driving.sim.park_sensors import sensor_config

    try:
        sensor_config(text)
    except ValueError as exc:
        raise argparse.ArgumentTypeError(str(exc)) from None
    return [n.strip() for n in text.split(",") if n.strip()]


def sensor_env(args: argparse.Namespace) -> dict:
    """The ``GarageDriveEnv`` keyword argument of the sensor options (``sensors``: a dict of
    :class:`~garage_mj.driving.sim.park_sensors.SensorConfig` fields), none when no sensor is asked for."""
    from garage_mj.driving.sim.park_sensors import sensor_config

    if not args.sensors:
        if args.slot_noise is not None:
            raise UserError("--slot-noise is the slot detector's: give --sensors slot (or all) too")
        return {}
    cfg = {k: v for k, v in vars(sensor_config(args.sensors)).items() if v is True}
    if args.slot_noise is not None:
        if not cfg.get("slot"):
            raise UserError("--slot-noise is the slot detector's: add slot to --sensors")
        cfg["slot_position_sigma"], cfg["slot_yaw_sigma"] = args.slot_noise
        try:
            sensor_config(cfg)
        except ValueError as exc:
            raise UserError(f"--slot-noise: {exc}") from None
    return {"sensors": cfg}


def add_task_args(p: argparse.ArgumentParser, stall: bool = False) -> None:
    """``--task`` and ``--maneuver`` (and ``--stall``): what each test asks of the driver (docs/spec.md 7 and 8)."""
    p.add_argument("--task", choices=TASKS, default="cruise",
                   help="cruise: entrance to the lane beside the stall (default); park: from there into the stall, "
                        "forward and reverse; avp: both, scored as one test. Stored in run.json like the seed")
    p.add_argument("--maneuver", choices=MANEUVER_CHOICES, default="reverse",
                   help="park and avp: reverse-in (default), forward (nose-in), or any (drawn per test)")
    if stall:
        p.add_argument("--stall", type=non_negative_int, metavar="ID",
                       help="test this stall every time (default: drawn per test); an id a garage lacks is "
                            "refused before anything is written, naming its range")


def task_warning(command: str, driver: str, task: str) -> None:
    """One line on stderr when a park or AVP run's driver cannot reverse: its class does not name the task in a
    ``tasks`` attribute (a cruise driver: its actions keep the car in D). The tests still run."""
    from garage_mj.driving.drivers import resolve_driver

    if task == "cruise":
        return
    tasks = getattr(resolve_driver(driver), "tasks", ("cruise",))
    if task not in tasks:
        print(f"garage-mj {command}: warning: driver {driver!r} is a cruise driver (its class declares no "
              f"tasks = (..., {task!r})): it cannot select reverse, so it drives the {task} tests forward only",
              file=sys.stderr)


#: The most --workers of cruise and hunt: more processes than tests or cores only cost memory.
MAX_WORKERS = 1024


def test_seconds(text: str) -> float:
    """argparse type of --test-timeout: a number of seconds > 0, at most :data:`MAX_TEST_TIMEOUT`."""
    value = positive_seconds(text)
    if value > MAX_TEST_TIMEOUT:
        raise argparse.ArgumentTypeError(f"{text} is too long: give at most {MAX_TEST_TIMEOUT:,.0f} seconds")
    return value


def video_count(text: str) -> int:
    """argparse type of --videos: how many tests to record (an integer >= 0), not a file name."""
    try:
        return non_negative_int(text)
    except argparse.ArgumentTypeError:
        raise argparse.ArgumentTypeError(
            f"{text!r}: give how many tests to record into OUT/videos/ (e.g. --videos 3), not a file name") from None


@contextlib.contextmanager
def action_warnings(command: str) -> Iterator[None]:
    """Print each ``ActionTypeWarning`` (a driver run with another action type than its own) as one line,
    ``garage-mj <command>: warning: ...``; other warnings as Python prints them."""
    from garage_mj.driving.drivers import ActionTypeWarning

    shown = warnings.showwarning

    def show(message, category, filename, lineno, file=None, line=None):
        if issubclass(category, ActionTypeWarning):
            print(f"garage-mj {command}: warning: {message}", file=sys.stderr)
        else:
            shown(message, category, filename, lineno, file, line)

    with warnings.catch_warnings():
        warnings.simplefilter("always", ActionTypeWarning)
        warnings.showwarning = show
        yield


def sources(args: argparse.Namespace) -> list:
    """The garages to test, from ``--packs`` or ``--library`` with the filters."""
    if args.packs is not None:
        if not args.packs.is_dir():
            raise UserError(f"--packs {args.packs}: no such folder; export packs with garage-mj export")
        if any(v is not None for v in (args.map, args.difficulty, args.coverage, args.route_difficulty, args.sample,
                                       args.ids)):
            raise UserError("--map/--difficulty/--coverage/--route-difficulty/--sample/--ids filter a --library, "
                            "not --packs")
        dirs = sorted(d for d in args.packs.iterdir() if (d / MANIFEST).is_file())
        if args.limit is not None:
            dirs = dirs[: args.limit]
        found = [CruiseSource.from_pack(d) for d in dirs]
    else:
        if not args.library.is_file():
            raise LibraryError(f"{args.library}: no such library file; build one with garage-mj train")
        with Library(args.library, create=False) as lib:
            f = filters(args)
            if args.ids is not None:
                records = records_by_id(lib, args)
            elif args.sample is not None:
                records = lib.sample(args.sample, args.seed, **f)
                records = records[: args.limit] if args.limit is not None else records
            else:
                records = lib.query(limit=args.limit, **f)
            records = lib.verified(records) if args.ids is None else records  # hash and metrics recomputed: an altered row is refused by id
        found = [CruiseSource.from_record(r) for r in records]
    if not found:
        raise UserError("no garages match; check the source folder or loosen the filters")
    return found


def geometry_env(args: argparse.Namespace, srcs: list) -> dict:
    """``{"world": the park geometry}`` for the drive env (docs/spec.md section 9), only when it is not the default
    (so a default run's ``run.json`` stays as it was). Packs bring the geometry they were built in: the options, when
    given, must name it; every garage must hold it (else one line names the block and the fix)."""
    from garage_mj.export.pack import check_geometry, manifest_world

    world = geometry_world(args)
    asked = args.layout is not None or any(getattr(args, k) is not None for k in geometry(world))
    packs = {}
    for src in srcs:
        if src.pack:
            packs[src.name] = manifest_world(json.loads((Path(src.pack) / MANIFEST).read_text()), src.pack)
    built = {tuple(sorted(geometry(w).items())): (name, w) for name, w in packs.items()}
    if len(built) > 1:
        raise UserError(f"--packs {args.packs}: its packs were built in {len(built)} park geometries; cruise one "
                        "geometry per run (a folder of packs of one geometry)")
    if built:
        name, pack_world = next(iter(built.values()))
        if asked and geometry(pack_world) != geometry(world):
            raise UserError(f"pack {name} was built in another park geometry ({pack_world.stall_width:g} m x "
                            f"{pack_world.stall_length:g} m stalls at {pack_world.stall_angle:g} degrees, "
                            f"{pack_world.aisle_width:g} m aisles); leave the geometry options out to cruise in its "
                            "own, or export the packs in the geometry asked for")
        world = pack_world
    check_geometry([src.garage for src in srcs], world)
    return {} if world.is_default_geometry else {"world": geometry(world)}


def add_actor_arguments(group: argparse._ActionsContainer, per: str = "test") -> None:
    """The actor options of a command whose tests (or training episodes: ``per``) may hold actors: ``--pedestrians``,
    ``--moving-cars``, ``--clutter`` and ``--scenario``, read back by :func:`scenario`."""
    group.add_argument("--pedestrians", type=non_negative_int, metavar="N",
                       help=f"pedestrians per {per}: crossing, stepping out between parked cars, walking along")
    group.add_argument("--moving-cars", type=non_negative_int, metavar="M",
                       help=f"moving cars per {per}: reversing out of a stall, oncoming, waiting at a junction")
    group.add_argument("--clutter", type=non_negative_int, metavar="K",
                       help=f"static clutter per {per}: cones, trolleys, a badly parked car")
    group.add_argument("--scenario", metavar="NAME|FILE.toml",
                       help="a named scenario (" + ", ".join(SCENARIOS) + ": park and avp tests' actors around the "
                            "target stall) or a TOML file of every ScenarioConfig field ([scenario] table: "
                            "behaviours, speeds, trigger lead, reaction time, braking); the three flags above "
                            "override its counts")


def scenario(args: argparse.Namespace) -> dict | None:
    """The ScenarioConfig fields of --scenario and the count flags (None: no actors asked for)."""
    counts = {"pedestrians": args.pedestrians, "moving_cars": args.moving_cars, "clutter": args.clutter}
    if args.scenario is None and all(v is None for v in counts.values()):
        return None
    named = args.scenario in SCENARIOS
    if named and args.scenario.startswith("park_") and getattr(args, "task", "cruise") == "cruise":
        raise UserError(f"--scenario {args.scenario}: its actors stand around a target stall; run it with --task park "
                        "or --task avp")
    if args.scenario is not None and not named and not Path(args.scenario).is_file():
        raise UserError(f"--scenario {args.scenario}: no such file or scenario; give a TOML file with a [scenario] "
                        f"table or one of {', '.join(SCENARIOS)}")
    cfg = load_scenario_config(args.scenario if named or args.scenario is None else Path(args.scenario), **counts)
    data = {f: getattr(cfg, f) for f in cfg.__dataclass_fields__}
    return {k: list(v) if isinstance(v, tuple) else v for k, v in data.items()}


def route_text(stats: dict) -> str:
    """The closing line's route difficulty part: r under the model, named with what it was fitted for, or why
    there is none (no shipped model was fitted on this driver and action type)."""
    fitted = stats.get("route_model_fitted_for")
    if not stats.get("route_model") or not fitted:
        return ("no route difficulty (no shipped model was fitted on this driver with these actions; "
                "--route-model FILE gives one)")
    on = ", ".join(fitted["drivers"]) or "unknown drivers"
    actions = " or ".join(fitted["action_types"]) or "unknown"
    return (f"r(route difficulty, success) = {r_text(stats['route_r'], stats['route_n'])} (model "
            f"{stats['route_model_name']}, fitted on {on} with {actions} actions)")


def replay(args: argparse.Namespace) -> int:
    if args.videos:
        raise UserError("--videos records tests of a batch (--packs or --library), not --scenario-file replays")
    if args.report:
        raise UserError("--report reports a batch (--packs or --library), not --scenario-file replays")
    if args.pictures is not None:
        raise UserError("--pictures draws tests of a park or AVP batch (--packs or --library), not --scenario-file "
                        "replays")
    if args.ids is not None:
        raise UserError("--ids picks garages of a --library, not --scenario-file replays")
    if args.action_type is not None:
        raise UserError("--action-type: a --scenario-file replay runs with the action type the file records "
                        "(another --driver: that driver's own); leave it out")
    rows = []
    for path in args.scenario_file:
        if not path.is_file():
            raise UserError(f"--scenario-file {path}: no such file; write tests with garage-mj cruise --xosc")
        row = replay_xosc(path, driver=args.driver)
        rows.append(row)
        extra = f" ({row['hit']})" if row["hit"] else ""
        print(f"{path}: {row['outcome']}{extra} after {row['time']} s, driver {row['driver']}: {row['reason']}")
    out = ensure_dir(args.out, "--out")
    buf = io.StringIO(newline="")
    w = csv.DictWriter(buf, fieldnames=("file", *TEST_COLUMNS), extrasaction="ignore")
    w.writeheader()
    for path, row in zip(args.scenario_file, rows, strict=True):
        w.writerow({"file": str(path), **row})
    atomic_write(out / "replay.csv", buf.getvalue())
    print(f"{len(rows)} replayed; rows in {out / 'replay.csv'}")
    return 0


def runner_failures(failures: dict[str, int]) -> str:
    """``1 driver_crash, 2 driver_timeout``: the tests whose driver's process died or hung, by kind ("" for none)."""
    return ", ".join(f"{failures[k.value]} {k.value}" for k in RUNNER_KINDS if failures.get(k.value))


def closing_lines(s: dict, new: int, action_label: str, out: Path) -> list[str]:
    """What a run prints when its tests are done, naming its task. A cruise run: its success and the Pearson r of
    success on the paper's difficulty beside the paper's (docs/spec.md section 7). A park or AVP run is judged by
    section 9 instead: its success, then by level, maneuver and stall angle, and its figure; no cruise regression."""
    from garage_mj.reporting.park_figure import PARK_FIGURE  # matplotlib: deferred

    task = s.get("task", "cruise")
    unproven = f", {s['unproven']} unproven ({s['unproven_pct']}%, excluded)" if "unproven" in s else ""
    done = (f"{s['infeasible']} infeasible (excluded){unproven}, success {s['success_pct']}% of {s['feasible']} "
            f"feasible ({action_label})")
    if task == "cruise":
        return [f"{s['tests']} tests on {s['garages']} garages ({new} new): {done}, Pearson r(difficulty, success) = "
                f"{r_text(s['r'], s['n'])} (paper {s['paper_r']}), {route_text(s)}; results in {out}"]
    lines = [f"{count_noun(s['tests'], f'{task_noun(task)} test')} ({s.get('maneuver', 'reverse')}) on "
             f"{count_noun(s['garages'], 'garage')} ({new} new): {done}; results in {out}"]
    if "by_level" in s:  # its success by level, maneuver and stall angle (docs/spec.md section 9)
        lines += [f"  {line}" for line in breakdown_lines({k: s[k] for k in BREAKDOWNS})]
    if (out / PARK_FIGURE).is_file():
        lines.append(f"  {task_noun(task)} success by level and maneuver: {out / PARK_FIGURE}")
    if s.get("park_model"):  # whose failure probability tests.csv's park_difficulty is
        fitted = ", ".join(s.get("park_model_fitted_for") or []) or "unknown drivers"
        lines.append(f"  park_difficulty in tests.csv: model {s['park_model_name']} (fitted on {fitted})"
                     + (" - not this driver's own; --park-model FILE gives one" if s.get("park_note") else ""))
    return lines


def run(args: argparse.Namespace) -> int:
    from garage_mj.driving.cruise import check_stall, check_task, run_world
    from garage_mj.reporting.cruise import run_cruise  # matplotlib, for regression.png

    if (args.scenario_file is not None or args.cases is not None) and vehicle_env(args):
        given = "--scenario-file replays the vehicles its file records" if args.cases is None else \
            "--cases tests the car and the obstacles each case file gives"
        raise UserError(f"--vehicle, --parked-fleet and --parked-jitter choose the cars of a --packs or --library run; "
                        f"{given}: leave them out")
    if (args.scenario_file is not None or args.cases is not None) and sensor_env(args):
        raise UserError("--sensors adds observations to a --packs or --library run; a --scenario-file or --cases run "
                        "drives with the default ones: leave it out")
    if args.scenario_file is not None:
        return replay(args)
    if args.cases is not None:
        from garage_mj.cli.cruise_cases import run_cases_cli

        return run_cases_cli(args, action_warnings, task_warning)
    if args.pictures is not None and args.task == "cruise":
        raise UserError("--pictures draws park and AVP tests from above (--task park or avp); watch a cruise run's "
                        "tests with --videos N")
    if args.park_model is not None and args.task == "cruise":
        raise UserError("--park-model rates park and AVP tests; give --task park or avp, or leave it out")
    args.driver = args.driver or "vision"
    srcs = sources(args)
    env = geometry_env(args, srcs)
    scen = scenario(args)
    if scen is not None:
        env["scenario"] = scen
    env.update(vehicle_env(args))
    env.update(sensor_env(args))
    env.update(guide_env(args))
    with action_warnings("cruise"):
        settings = CruiseSettings(args.driver, args.seed, args.action_type, args.occupancy, env,
                                  test_timeout=args.test_timeout, task=args.task, maneuver=args.maneuver,
                                  stall=args.stall)
        check_task(settings)  # refused before the warning below, as run_cruise would
        check_stall(srcs, settings.stall, run_world(settings))
        task_warning("cruise", args.driver, args.task)
        res = run_cruise(srcs, args.tests, settings, args.out, compute=compute(args), xosc=args.xosc,
                         route_model=args.route_model or True, park_model=args.park_model or True)
    s = res.stats
    for line in closing_lines(s, res.tests_run, res.action_label, res.out_dir):
        print(line)
    lost = runner_failures(s["failures"])
    if lost:
        print(f"{lost}: the driver's process died or hung (reasons in {res.out_dir / 'tests.csv'})")
    if args.videos:
        from garage_mj.reporting.cruise import record_cruise_videos

        made = record_cruise_videos(res, srcs, args.videos)
        print(f"{len(made)} video(s) in {res.out_dir / 'videos'}" + (":" if made else
                                                                      " (no driven test to record)"))
        for path, row in made:
            print(f"  {path.name}: {row['outcome']}{' (' + row['hit'] + ')' if row['hit'] else ''}: {row['reason']}")
    if args.report:
        from garage_mj.reporting.run_report import REPORT_FAILURES, cruise_report

        print(f"report: {cruise_report(res.out_dir, srcs, max(REPORT_FAILURES, args.videos or 0), args.pictures or 'failures')}")
    elif args.pictures is not None and args.task != "cruise":  # pictures asked for without a report
        from garage_mj.reporting.park import PICTURES, record_park_pictures
        from garage_mj.reporting.run_report import REPORT_FAILURES

        made = record_park_pictures(res.out_dir, res.rows, srcs, max(REPORT_FAILURES, args.videos or 0), args.pictures)
        print(f"{len(made)} top-down picture(s) in {res.out_dir / PICTURES}")
    return 0
