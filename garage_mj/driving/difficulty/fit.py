"""Fit and check the route-aware difficulty on recorded cruise outcomes (``garage-mj difficulty fit``).

A cruise run folder (:mod:`garage_mj.driving.cruise`) holds ``tests.csv`` (one row per test: garage
hash, target stall, outcome) and ``garages.json`` (its garages, :class:`~garage_mj.driving.garage_set.GarageSet`);
runs written before ``garages.json`` existed find their garages by hash in a ``library``.
:func:`test_records` (:func:`load_runs`, also each garage's route difficulty) turns the feasible tests of runs into records: the route features of the
test's planned route (:mod:`garage_mj.scene.route_features`), whether it failed, the driver and
the paper's difficulty. :func:`fit_runs` fits a :class:`~garage_mj.scene.route_difficulty.RouteDifficulty`
on them and writes the model with its fitting data beside it (``<model>.fit.csv``), so anyone can
refit on their own driver's results. :func:`score` measures how well a difficulty predicts the
failures of other records: per-garage Pearson r with success % (95 % bootstrap interval over
garages) and per-test AUC, for the route difficulty and for the paper's, next to the largest |r|
that the garages' numbers of tests let any difficulty expect (:func:`~garage_mj.driving.difficulty.regression.attainable_r`).
"""

from __future__ import annotations

import csv
import io
import json
from collections import defaultdict
from collections.abc import Sequence
from pathlib import Path
from typing import Any

import numpy as np

from garage_mj.core.errors import GarageMJError
from garage_mj.core.fsutil import atomic_write
from garage_mj.driving.cruise import GARAGES_FILE
from garage_mj.driving.difficulty.regression import (
    attainable_r,
    auc,
    bootstrap_attainable_r,
    bootstrap_r,
    joint_r_bound,
    pearson,
)
from garage_mj.driving.garage_set import GarageSet, GarageSetError
from garage_mj.driving.results import read_tests, rounded
from garage_mj.driving.sources import CruiseSource
from garage_mj.generation.library import Library
from garage_mj.generation.library_format import LibraryError
from garage_mj.scene.route_difficulty import RouteDifficulty, fit
from garage_mj.scene.route_features import FEATURES, garage_features, plan_features

RECORD_COLUMNS = ("run", "driver", "garage", "garage_hash", "test", "target_stall", "outcome", "failed",
                  "difficulty", *FEATURES)


class DifficultyFitError(GarageMJError):
    """Cruise results cannot be read for a fit (no tests.csv, garages not found)."""


def _run_sources(run: Path, library: Path | None, hashes: set[str]) -> dict[str, CruiseSource]:
    """garage hash -> source of a run's garages: its garages.json, else the library's garages with ``hashes``."""
    if (run / GARAGES_FILE).is_file():
        try:
            return {s.hash: s for s in GarageSet.from_json(run / GARAGES_FILE)}
        except GarageSetError as exc:
            raise DifficultyFitError(str(exc)) from None
    if library is None:
        raise DifficultyFitError(f"{run} has no {GARAGES_FILE} (a run of an older garage-mj); pass --library FILE, "
                                 "the library its garages came from")
    out = {}
    try:
        with Library(library, create=False) as lib:
            for h in sorted(hashes):
                i = lib.id_of(h)
                if i is not None:
                    out[h] = CruiseSource.from_record(lib.get(i))
    except LibraryError as exc:
        raise DifficultyFitError(str(exc)) from None
    return out


def _run_tests(run: Path) -> list[dict[str, str]]:
    if not (run / "tests.csv").is_file():
        raise DifficultyFitError(f"{run} holds no tests.csv; pass cruise run folders (garage-mj cruise --out)")
    rows = read_tests(run / "tests.csv")
    park = next((r["task"] for r in rows if r["task"] != "cruise"), None)
    if park is not None:
        raise DifficultyFitError(f"{run} is a {park} run, not a cruise run; its tests have a park difficulty "
                                 "(--task park), not a route difficulty")
    return rows


def test_records(runs: Sequence[str | Path], library: str | Path | None = None, progress: bool = False
                 ) -> list[dict[str, Any]]:
    """One record per feasible test of ``runs`` (cruise run folders): its route features and outcome."""
    return load_runs(runs, library, progress=progress)[0]


def load_runs(runs: Sequence[str | Path], library: str | Path | None = None, model: RouteDifficulty | None = None,
              progress: bool = False) -> tuple[list[dict[str, Any]], dict[str, float]]:
    """:func:`test_records` of ``runs``, and with ``model`` each tested garage's route difficulty (garage hash ->
    value over all its feasible stalls; NaN: none), both from one plan per garage whatever the runs share."""
    from garage_mj.scene.drivable import drive_planner
    from garage_mj.scene.garage_scene import GarageScene

    lib = Path(library) if library is not None else None
    todo: list[tuple[Path, dict[str, str], CruiseSource]] = []
    for run in map(Path, runs):
        rows = _run_tests(run)
        sources = _run_sources(run, lib, {r["garage_hash"] for r in rows})
        for row in rows:
            src = sources.get(row["garage_hash"])
            if src is None:
                if row["feasible"] != "1":
                    continue
                where = f"{run / GARAGES_FILE}" if (run / GARAGES_FILE).is_file() else str(lib)
                raise DifficultyFitError(f"{run}: garage {row['garage']} ({row['garage_hash'][:12]}) is not in {where}; "
                                         "pass the library the run's garages came from")
            todo.append((run, row, src))
    todo.sort(key=lambda t: t[2].hash)  # one planner per garage
    out: list[dict[str, Any]] = []
    per_garage: dict[str, float] = {}
    planner, current = None, None
    from tqdm import tqdm

    for run, row, src in tqdm(todo, desc="route features", unit="test", disable=not progress):
        if src.hash != current:
            scene = GarageScene(src.garage)
            planner, current = drive_planner(scene), src.hash
            if model is not None:  # the same planner: the tests' stalls are planned once
                per_garage[src.hash] = model.of_features(garage_features(scene))
        if row["feasible"] != "1":
            continue
        plan = planner.plan(int(row["target_stall"]))
        if not plan.feasible:
            raise DifficultyFitError(f"{run}: test {row['test']} of {row['garage']} was driven but stall "
                                     f"{row['target_stall']} has no feasible route now ({plan.reason}); "
                                     "the run was made with other planner settings")
        out.append({"run": str(run), "driver": row["driver"], "garage": row["garage"],
                    "garage_hash": row["garage_hash"], "test": int(row["test"]),
                    "target_stall": int(row["target_stall"]), "outcome": row["outcome"],
                    "failed": int(row["outcome"] != "success"), "difficulty": float(row["difficulty"]),
                    **plan_features(planner, plan)})
    return out, per_garage


def write_records(path: str | Path, records: Sequence[dict[str, Any]],
                  columns: Sequence[str] = RECORD_COLUMNS) -> None:
    """``records`` as a CSV of ``columns`` (a fit's data file), floats to 6 places, written atomically."""
    buf = io.StringIO()
    w = csv.DictWriter(buf, fieldnames=list(columns), lineterminator="\n")
    w.writeheader()
    for r in records:
        w.writerow({k: (round(v, 6) if isinstance(v, float) else v) for k, v in r.items() if k in columns})
    atomic_write(Path(path), buf.getvalue())


def read_records(path: str | Path) -> list[dict[str, Any]]:
    with open(path, newline="") as f:
        rows = list(csv.DictReader(f))
    num = set(FEATURES) | {"difficulty"}
    return [{k: (float(v) if k in num else int(v) if k in ("failed", "test", "target_stall") else v)
             for k, v in r.items()} for r in rows]


def _check_out(out: Path, data: Path) -> None:
    """Refuse an ``out`` (or its ``.fit.csv``) that names a folder, or lies under a file."""
    for path in (out, data):
        if path.is_dir():
            raise DifficultyFitError(f"--out {out}: {path} is a folder; give the path of the model file to write "
                                     "(e.g. my_route_difficulty.json)")
    above = next((p for p in out.parents if p.exists()), None)
    if above is not None and not above.is_dir():
        raise DifficultyFitError(f"--out {out}: {above} is a file, not a folder; give a path in a folder")


def _action_types(runs: Sequence[str | Path]) -> list[str]:
    """The action types the cruise runs used (their ``run.json``), what a cruise run's default route model is
    matched on (:func:`garage_mj.driving.difficulty.rating.choose_route_model`)."""
    types = set()
    for run in runs:
        try:
            types.add(json.loads((Path(run) / "run.json").read_text())["action_type"])
        except (OSError, ValueError, KeyError, TypeError):
            continue  # a run of an older garage-mj: its type is not known
    return sorted(t for t in types if isinstance(t, str))


def fit_runs(runs: Sequence[str | Path], out: str | Path, library: str | Path | None = None,
             features: Sequence[str] = FEATURES, progress: bool = True) -> tuple[RouteDifficulty, list[dict[str, Any]]]:
    """Fit a route difficulty on the feasible tests of ``runs``; writes ``out`` and ``<out stem>.fit.csv``.

    Both paths are checked before the runs are read, so a bad ``out`` writes neither."""
    out = Path(out)
    data = out.with_suffix(".fit.csv")
    _check_out(out, data)
    records = test_records(runs, library, progress)
    drivers = sorted({r["driver"] for r in records})
    try:
        model = fit(records, [r["failed"] for r in records], features,
                    info={"runs": [str(r) for r in runs], "drivers": drivers, "action_types": _action_types(runs),
                          "garages": len({r["garage_hash"] for r in records}), "fit_data": data.name})
    except ValueError as exc:
        raise DifficultyFitError(f"cannot fit on {len(records)} tests of {len(runs)} run(s): {exc}") from None
    model.fit["in_sample"] = score(model, records)
    out.parent.mkdir(parents=True, exist_ok=True)
    write_records(data, records)
    model.save(out)
    return model, records


def garage_table(model: RouteDifficulty, records: Sequence[dict[str, Any]]) -> list[dict[str, Any]]:
    """Per (driver, garage): tests, success %, the paper's difficulty and the mean route difficulty of its tests."""
    out = []
    for (driver, h), rs in _by_garage(records):
        p = model.test_probability(rs)
        out.append({"driver": driver, "garage": rs[0]["garage"], "garage_hash": h, "tests": len(rs),
                    "success_pct": _success_pct(rs), "difficulty": rs[0]["difficulty"],
                    "route_difficulty": float(np.mean(p))})
    return out


def _by_garage(records: Sequence[dict[str, Any]]) -> list[tuple[tuple[str, str], list[dict[str, Any]]]]:
    """The records grouped per (driver, garage hash), sorted by that key."""
    groups: dict[tuple[str, str], list[dict[str, Any]]] = defaultdict(list)
    for r in records:
        groups[(r["driver"], r["garage_hash"])].append(r)
    return sorted(groups.items())


def _success_pct(records: Sequence[dict[str, Any]]) -> float:
    return 100.0 * (1 - np.mean([r["failed"] for r in records]))


def score(model: RouteDifficulty, records: Sequence[dict[str, Any]], seed: int = 0,
          garage_route: dict[str, float] | None = None) -> dict[str, dict[str, Any]]:
    """Per driver in ``records``: per-garage r (with a 95 % bootstrap interval) and per-test AUC of both difficulties.

    The per-garage route difficulty is the mean over the garage's tests of their failure probability,
    or ``garage_route[hash]`` when given (the expectation over all its feasible stalls).
    """
    out: dict[str, dict[str, Any]] = {}
    table = garage_table(model, records)
    for driver in sorted({r["driver"] for r in records}):
        recs = [r for r in records if r["driver"] == driver]
        rows = [t for t in table if t["driver"] == driver]
        succ = [t["success_pct"] for t in rows]
        route = [garage_route[t["garage_hash"]] if garage_route else t["route_difficulty"] for t in rows]
        paper = [t["difficulty"] for t in rows]
        failed = [bool(r["failed"]) for r in recs]
        per_garage = [t["tests"] for t in rows]
        out[driver] = {
            "garages": len(rows), "tests": len(recs), "success_pct": round(100.0 * (1 - np.mean(failed)), 2),
            # the best |r| any per-garage difficulty can expect here, given each garage's number of tests
            "attainable_r": rounded(attainable_r(succ, per_garage)),
            "attainable_r_ci95": [rounded(v) for v in bootstrap_attainable_r(succ, per_garage, seed)],
            "route": {"r": rounded(pearson(route, succ)), "r_ci95": [rounded(v) for v in bootstrap_r(route, succ, seed)],
                      "auc": rounded(auc(model.test_probability(recs), failed))},
            "paper": {"r": rounded(pearson(paper, succ)), "r_ci95": [rounded(v) for v in bootstrap_r(paper, succ, seed)],
                      "auc": rounded(auc([r["difficulty"] for r in recs], failed))},
        }
    return out


def driver_agreement(records: Sequence[dict[str, Any]]) -> dict[str, dict[str, Any]]:
    """Per pair of drivers in ``records`` (``"a+b"``): Pearson r between their per-garage success % over the
    garages both drove, and the largest |r| any one difficulty can have with both, with the same sign
    (harder for both; :func:`~garage_mj.driving.difficulty.regression.joint_r_bound`). Drivers that fail alike correlate highly; a
    difficulty fitted on one then transfers to the other, and otherwise it cannot."""
    success: dict[str, dict[str, float]] = {}
    for (driver, h), rs in _by_garage(records):
        success.setdefault(driver, {})[h] = _success_pct(rs)
    drivers = sorted(success)
    out = {}
    for i, a in enumerate(drivers):
        for b in drivers[i + 1:]:
            shared = sorted(set(success[a]) & set(success[b]))
            r12 = pearson([success[a][h] for h in shared], [success[b][h] for h in shared]) if len(shared) > 2 \
                else float("nan")
            out[f"{a}+{b}"] = {"garages": len(shared), "r_between": rounded(r12), "best_joint_abs_r": rounded(joint_r_bound(r12))}
    return out

