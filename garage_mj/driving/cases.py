"""Park tests from problem files (docs/spec.md section 9, "Cases from elsewhere"): ``garage-mj cruise --cases PATH...``.

A problem file is one park test: this project's park problem (JSON, ``garage-mj export --park-problems``) or a case
of the TPCAP parking benchmark (one comma-separated line: start x, y, yaw; goal x, y, yaw, both of the rear-axle
midpoint; the obstacle count n; n vertex counts; the vertices' x, y). :func:`read_case` reads one into a
:class:`~garage_mj.scene.case_scene.ParkCase` through the project's readers
(:func:`~garage_mj.export.park_problems.read_park_problem`, :func:`~garage_mj.export.park_problems.read_tpcap_case`),
which refuse a malformed file in one line naming it (:class:`~garage_mj.export.park_problems.ParkProblemError`); a
polygon that crosses itself is refused the same way. A folder stands for the problem files under it (``*.json``
but the index ``park_problems.json``, and ``*.csv`` where no JSON of the same name stands beside it: an export
writes each problem both ways). The vehicle is the file's (a JSON problem's ``car``: the fleet's class of those
dimensions where there is one) or TPCAP's (:data:`~garage_mj.scene.vehicles.TPCAP_VEHICLE`).

:func:`run_cases` drives every case once with a driver (:class:`~garage_mj.driving.sim.case_env.CaseDriveEnv`) and
writes a cruise run's folder: ``tests.csv`` with one row per case (``garage``: the case file as given,
``garage_hash``: the SHA-256 of its bytes, ``test`` 0, ``target_stall`` 0, task ``park``, the case's maneuver, the
parking metrics; the paper's difficulty columns stay empty: a case is no garage), appended as each case ends so
that a re-run resumes; ``run.json`` (the settings; a re-run with others is refused) and ``summary.json`` (the
counts: feasible, infeasible by proof and unproven, success over the feasible ones with the unproven share beside
it, the failures and the park metrics, as a park run's). A case's verdict is the reference planner's, as a garage
park test's: ``feasible`` (a plan), ``infeasible`` (a proof: the start or the goal is not clear of the obstacles,
or the goal is closed at the car's width) or ``unproven`` (no plan within the escalated budget, no proof); a case
that starts far from its goal escalates further (:data:`~garage_mj.scene.case_scene.CASE_PARK`).
"""

from __future__ import annotations

import csv
import hashlib
import os
import time
from collections.abc import Iterable, Iterator, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import TYPE_CHECKING, Any

from garage_mj.core.backends import DEFAULT_COMPUTE, Compute, LostJob, check_backend, map_unordered
from garage_mj.core.fsutil import FolderLock, clean_temp, ensure_dir, write_json
from garage_mj.driving.difficulty.park_rating import choose_park_model, park_difficulty_cell
from garage_mj.driving.episode import check_driver, drive_test
from garage_mj.driving.results import (
    TEST_COLUMNS,
    check_settings,
    failure_counts,
    park_breakdown,
    park_summary,
    parse_tests,
    repair_tests,
    write_csv,
)
from garage_mj.driving.sim.outcomes import NOT_DRIVEN, OUTCOMES, OutcomeKind
from garage_mj.driving.sources import CruiseError, CruiseSettings, cruise_seed
from garage_mj.export.park_problems import (
    INDEX,
    ParkProblemError,
    read_park_problem,
    read_tpcap_case,
)
from garage_mj.scene.case_scene import CaseObstacle, CaseScene, ParkCase, convex_pieces, tpcap_class
from garage_mj.scene.park_planning import ParkPlan
from garage_mj.scene.vehicles import FLEET, TPCAP_VEHICLE, VehicleClass

if TYPE_CHECKING:
    from garage_mj.driving.drivers import ActionChoice
    from garage_mj.scene.park_difficulty import ParkDifficulty

#: ``CruiseSettings.env`` of a run of cases: marks its ``run.json`` (a garage run into the folder is refused).
CASES_ENV = {"source": "cases"}
#: The most case files one run takes.
MAX_CASES = 100_000
_HEIGHT = 1.5  # [m] of a JSON problem's car (the file gives none)


# -- reading -----------------------------------------------------------------------------------------------------
def _digest(path: Path) -> str:
    try:
        return hashlib.sha256(path.read_bytes()).hexdigest()
    except OSError as exc:
        raise ParkProblemError(f"cannot read case {path}: {exc.strerror or exc}; give a case file") from None


def _vehicle(car: dict[str, float], path: Path) -> VehicleClass:
    """The vehicle of a JSON problem's ``car``: the fleet's class of those dimensions, else a class of its own."""
    for v in FLEET.values():
        if all(abs(a - b) < 1e-9 for a, b in ((v.wheelbase, car["wheelbase"]), (v.length, car["length"]),
                                               (v.width, car["width"]), (v.front_overhang, car["front_overhang"]),
                                               (v.max_steer, car["max_steer"]))):
            return v
    try:
        return VehicleClass("case", length=car["length"], width=car["width"], height=_HEIGHT,
                            wheelbase=car["wheelbase"], front_overhang=car["front_overhang"],
                            max_steer=car["max_steer"])
    except ValueError as exc:
        raise ParkProblemError(f"park problem {path}: its car is no vehicle ({exc}); give a car with overhangs > 0 "
                               "at both ends") from None


def _shifted(points, origin) -> tuple[tuple[float, float], ...]:
    return tuple((float(x) - origin[0], float(y) - origin[1]) for x, y in points)


def _checked(obstacles: list[CaseObstacle], path: Path) -> tuple[CaseObstacle, ...]:
    for k, o in enumerate(obstacles):
        try:
            convex_pieces(o.vertices)
        except ValueError as exc:
            raise ParkProblemError(f"case {path}: obstacle {k + 1} is no simple polygon ({exc}); give its vertices "
                                   "in order round its outline") from None
    return tuple(obstacles)


def _is_json(path: Path) -> bool:
    if path.suffix.lower() == ".json":
        return True
    if path.suffix.lower() == ".csv":
        return False
    try:
        with open(path, "rb") as f:
            return f.read(64).lstrip(b"\xef\xbb\xbf \t\r\n").startswith(b"{")
    except OSError:
        return False


def read_case(path: str | Path) -> ParkCase:
    """The :class:`ParkCase` of the problem file ``path`` (module docstring); ParkProblemError, one line naming the
    file, for a file that is none."""
    path = Path(path)
    if _is_json(path):
        p = read_park_problem(path)
        origin = p.start[:2]
        obstacles = [CaseObstacle(cls, _shifted(vs, origin)) for cls, vs in p.obstacles]
        return ParkCase(name=path.name, source=str(path), digest=_digest(path), kind="garage-mj",
                        origin=(float(origin[0]), float(origin[1])), vehicle=_vehicle(p.car, path),
                        start=(0.0, 0.0, float(p.start[2])),
                        goal=(p.goal[0] - origin[0], p.goal[1] - origin[1], float(p.goal[2])),
                        obstacles=_checked(obstacles, path), stall_outline=_shifted(p.stall_outline, origin),
                        maneuver=p.maneuver)
    start, goal, polys = read_tpcap_case(path)
    origin = start[:2]
    obstacles = [CaseObstacle(tpcap_class(_shifted(poly, origin)), _shifted(poly, origin)) for poly in polys]
    return ParkCase(name=path.name, source=str(path), digest=_digest(path), kind="tpcap",
                    origin=(float(origin[0]), float(origin[1])), vehicle=TPCAP_VEHICLE,
                    start=(0.0, 0.0, float(start[2])), goal=(goal[0] - origin[0], goal[1] - origin[1], float(goal[2])),
                    obstacles=_checked(obstacles, path))


def case_files(paths: Iterable[str | Path]) -> list[Path]:
    """The problem files ``paths`` stand for: a file as it is, a folder as its problem files (module docstring), in
    order; ParkProblemError for a path that is neither, or a folder without one."""
    out: list[Path] = []
    for p in map(Path, paths):
        if p.is_dir():
            found = sorted(q for q in p.rglob("*") if q.is_file() and q.suffix.lower() in (".json", ".csv")
                           and q.name != INDEX)
            stems = {q.with_suffix("") for q in found if q.suffix.lower() == ".json"}
            found = [q for q in found if q.suffix.lower() == ".json" or q.with_suffix("") not in stems]
            if not found:
                raise ParkProblemError(f"--cases {p}: the folder holds no case file (*.csv or *.json); give case "
                                       "files or a folder of them")
            out += found
        elif p.is_file():
            out.append(p)
        else:
            raise ParkProblemError(f"--cases {p}: no such file or folder; give TPCAP case files (CaseN.csv) or park "
                                   "problems of garage-mj export --park-problems")
    if len(out) > MAX_CASES:
        raise ParkProblemError(f"--cases: {len(out):,} case files, more than {MAX_CASES:,}; give fewer")
    return out


def read_cases(paths: Iterable[str | Path]) -> list[ParkCase]:
    """Every case of ``paths`` (:func:`case_files`), read and checked before anything runs; the same case twice (the
    same bytes) is refused."""
    cases, seen = [], {}
    for path in case_files(paths):
        case = read_case(path)
        if case.digest in seen:
            raise ParkProblemError(f"--cases: {path} is the same case as {seen[case.digest]} (the same bytes); give "
                                   "each case once")
        seen[case.digest] = path
        cases.append(case)
    return cases


# -- running -----------------------------------------------------------------------------------------------------
@dataclass(frozen=True)
class _CaseSource:
    """What a test row names of where it ran (:func:`~garage_mj.driving.episode.drive_test`): the case file."""

    name: str
    hash: str
    difficulty: str = ""
    mean_road_length: str = ""
    mean_intersection_degree: str = ""


def case_settings(driver: str, seed: int = 0, action_type: str | None = None, **fields: Any) -> CruiseSettings:
    """The :class:`CruiseSettings` of a run of cases: task ``park``, the maneuver each case's own (``any``), no
    parked cars drawn, :data:`CASES_ENV` as ``env``."""
    return CruiseSettings(driver, seed, action_type, 0.0, dict(CASES_ENV), task="park", maneuver="any", **fields)


def case_env(case: ParkCase, settings: CruiseSettings, plan: ParkPlan | None = None):
    """The :class:`~garage_mj.driving.sim.case_env.CaseDriveEnv` of ``case`` for a run with ``settings`` (``plan``: its
    reference plan, when planned already)."""
    from garage_mj.driving.sim.case_env import CaseDriveEnv

    env = {k: v for k, v in settings.env.items() if k not in CASES_ENV}
    return CaseDriveEnv(CaseScene(case), action_type=settings.action_type, plan=plan, **env)


def plan_case(case: ParkCase) -> ParkPlan:
    """The reference plan of ``case`` (:attr:`~garage_mj.scene.case_scene.CaseScene.park_config`): its verdict before
    the drive."""
    return CaseScene(case).planner().plan_case()


def run_case(case: ParkCase, settings: CruiseSettings, plan: ParkPlan | None = None) -> dict[str, Any]:
    """Drive ``case`` once with ``settings`` (``plan``: its reference plan, planned here when None); its row."""
    start = time.perf_counter()
    env = case_env(case, settings, plan)
    try:
        seed = cruise_seed(settings.seed, case.digest, 0)
        obs, info = env.reset(seed=seed)
        row = drive_test(env, obs, info, seed, settings, _CaseSource(case.source, case.digest), 0, start)
    finally:
        env.close()
    if "vehicle" in row:  # the case's own, not a run setting's
        row["vehicle"] = case.vehicle.name
    return row


def _task(job: tuple[ParkCase, CruiseSettings, ParkPlan]) -> dict[str, Any]:
    return run_case(*job)


def _lost(job: tuple[ParkCase, CruiseSettings, ParkPlan], why: LostJob) -> dict[str, Any]:
    case, settings, _ = job
    kind = OutcomeKind.DRIVER_TIMEOUT if why.kind == "timeout" else OutcomeKind.DRIVER_CRASH
    return {**dict.fromkeys(TEST_COLUMNS, ""), "garage": case.source, "garage_hash": case.digest, "test": 0,
            "seed": cruise_seed(settings.seed, case.digest, 0), "driver": settings.driver, "outcome": kind.value,
            "reason": f"driver {settings.driver}: {why.reason}", "wall_s": round(why.seconds, 3), "task": "park",
            **({"vehicle": case.vehicle.name} if "vehicle" in TEST_COLUMNS else {})}


@dataclass(frozen=True)
class CaseResult:
    """Where a run of cases wrote its outputs, its rows (this run's cases, in their order) and its summary."""

    out_dir: Path
    tests_run: int
    rows: list[dict[str, str]]
    stats: dict[str, Any]
    action_label: str = ""
    cases: list[ParkCase] = field(default_factory=list)


_OUTCOME_NAMES = tuple(s.kind for s in OUTCOMES)


def _check_rows(path: Path, rows: Sequence[dict[str, str]], lines: Sequence[int], settings: CruiseSettings) -> None:
    """Refuse a resumed row that a run of cases with ``settings`` does not write (a :class:`CruiseError` line)."""
    for row, line in zip(rows, lines, strict=True):
        why = None
        if row["task"] != "park":
            why = "task", "is not park, the task of every case"
        elif row["driver"] != settings.driver:
            why = "driver", f"is not this run's driver ({settings.driver!r})"
        elif row["outcome"] not in _OUTCOME_NAMES:
            why = "outcome", f"is not a test outcome (one of {', '.join(_OUTCOME_NAMES)})"
        elif row["test"] != "0" or row["seed"] != str(cruise_seed(settings.seed, row["garage_hash"], 0)):
            why = "seed", f"is not the seed of this case under the run's seed {settings.seed}"
        if why is not None:
            col, text = why
            raise CruiseError(f"{path} line {line}: {col} {row[col][:40]!r} {text}; delete that line to run its case "
                              "again (or restore the file), or use another --out")


def case_summary(rows: Sequence[dict[str, Any]], settings: CruiseSettings, action_from: str) -> dict[str, Any]:
    """``summary.json`` of a run of cases: counts by verdict and outcome, success over feasible cases, park metrics, and
    success by level, maneuver and stall angle (:func:`~garage_mj.driving.results.park_breakdown`)."""
    kinds = [r["outcome"] for r in rows]
    driven = [r for r in rows if r["outcome"] not in NOT_DRIVEN]
    successes = kinds.count(OutcomeKind.SUCCESS.value)
    return {"cases": len(rows), "infeasible": kinds.count(OutcomeKind.INFEASIBLE.value), "feasible": len(driven),
            "successes": successes, "success_pct": round(100.0 * successes / len(driven), 2) if driven else None,
            "driver": settings.driver, "seed": settings.seed, "action_type": settings.action_type,
            "action_type_from": action_from, "task": "park", "failures": failure_counts(rows), **park_summary(rows),
            **park_breakdown(rows)}


def run_cases(cases: Sequence[ParkCase], settings: CruiseSettings, out_dir: str | Path = "cruise", *,
              compute: Compute = DEFAULT_COMPUTE, choice: ActionChoice | None = None,
              park_model: ParkDifficulty | str | Path | bool = True) -> CaseResult:
    """Drive every case of ``cases`` once (module docstring); resumable. ``settings``: :func:`case_settings`'s.
    ``park_model``: the model of each row's ``park_difficulty``, as :func:`garage_mj.driving.cruise.run_cruise`'s.
    Refuses a bad driver, a bad park model, a resumed folder of other settings or rows, in one line before anything
    is written."""
    from garage_mj.driving.cruise import check_task
    from garage_mj.driving.drivers import choose_action_type

    if not cases:
        raise CruiseError("no cases to run; give --cases with case files")
    choice = choice if choice is not None else choose_action_type(settings.driver, settings.action_type)
    check_backend(compute, reach=True)
    settings = settings.resolved(choice.action_type)
    check_task(settings)
    check_driver(settings)
    park = choose_park_model(park_model, settings.driver, settings.driver_kwargs)
    out = ensure_dir(out_dir, "--out")
    with FolderLock(out, "garage-mj cruise", remove=True):
        csv_path = out / "tests.csv"
        check_settings(out, settings, choice.source, write=False)
        parsed = parse_tests(csv_path)
        _check_rows(csv_path, parsed.rows, parsed.lines, settings)
        clean_temp(out)
        check_settings(out, settings, choice.source)
        rows = repair_tests(csv_path, parsed)
        done = {r["garage_hash"] for r in rows}
        jobs = [(c, settings) for c in cases if c.digest not in done]
        new = 0
        if jobs:
            if not csv_path.is_file():
                write_csv(csv_path, TEST_COLUMNS, [])
            with csv_path.open("a", newline="") as f:
                writer = csv.DictWriter(f, fieldnames=TEST_COLUMNS)
                for row in _rows(jobs, compute, settings):
                    if park.model is not None:
                        row["park_difficulty"] = park_difficulty_cell(park.model, row)
                    writer.writerow(row)
                    f.flush()
                    os.fsync(f.fileno())
                    rows.append({k: str(v) for k, v in row.items()})
                    new += 1
        by_hash = {r["garage_hash"]: r for r in rows}
        mine = [by_hash[c.digest] for c in cases if c.digest in by_hash]
        stats = {**case_summary(mine, settings, choice.source), **park.record()}
        write_json(out / "summary.json", stats)
        return CaseResult(out, new, mine, stats, choice.label, list(cases))


def _plans(cases: Sequence[ParkCase], compute: Compute) -> dict[str, ParkPlan]:
    """Every case's reference plan by its digest, on ``compute``'s backend: planned before the drives, so that
    ``--test-timeout`` bounds the driver alone (a case's search may take a minute where a garage's takes seconds)."""
    return {cases[k].digest: plan for k, plan in map_unordered(_plan_job, list(enumerate(cases)), compute=compute)}


def _plan_job(job: tuple[int, ParkCase]) -> tuple[int, ParkPlan]:
    return job[0], plan_case(job[1])


def _rows(jobs: list, compute: Compute, settings: CruiseSettings) -> Iterator[dict[str, Any]]:
    """Rows as cases end, on ``compute``'s backend; a drive past ``settings.test_timeout`` is a ``driver_timeout``."""
    from tqdm import tqdm

    plans = _plans([c for c, _ in jobs], compute)
    with tqdm(total=len(jobs), disable=not compute.progress, desc="cases", unit="case") as bar:
        for row in map_unordered(_task, [(c, st, plans[c.digest]) for c, st in jobs], compute=compute,
                                 timeout=settings.test_timeout, on_lost=_lost):
            bar.update()
            yield row


def stats_line(res: CaseResult) -> str:
    """The closing line of a run of cases."""
    s = res.stats
    return (f"{s['cases']} cases ({res.tests_run} new): {s['infeasible']} infeasible (excluded), {s['unproven']} "
            f"unproven ({s['unproven_pct']}%, excluded), success {s['success_pct']}% of {s['feasible']} feasible "
            f"({res.action_label}); results in {res.out_dir}")


__all__ = ["CASES_ENV", "CaseResult", "case_env", "case_files", "case_settings", "case_summary", "plan_case",
           "read_case", "read_cases", "run_case", "run_cases", "stats_line"]
