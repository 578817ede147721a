"""The park difficulty of park and AVP runs: fit it on their tests, score it against HOPE's levels, rate a run's tests.

A park or AVP run's ``tests.csv`` (``garage-mj cruise --task park|avp``) holds, per test, everything the park
difficulty reads (:func:`~garage_mj.scene.park_difficulty.park_features`), so no garage is rebuilt here.
:func:`load_park_runs` turns the driven tests of runs (outcomes ``infeasible`` and ``unproven`` left out) into
records; :func:`fit_park_runs` fits a :class:`~garage_mj.scene.park_difficulty.ParkDifficulty` on them and writes it
with its fitting data beside it (``<model>.fit.csv``); :func:`score_park` measures how well it predicts other
records' failures, side by side with HOPE's levels (normal 0, complex 1, extreme 2) on the same tests: per-test AUC,
and per-garage Pearson r with success % (a garage in one run, so in one geometry, is one point; 95 % bootstrap
interval over them). :func:`choose_park_model` picks a run's model (the driver's shipped one, else the default)
and :func:`park_difficulty_cell` fills a row's ``park_difficulty``.
"""

from __future__ import annotations

from collections import defaultdict
from collections.abc import Sequence
from pathlib import Path
from typing import Any

import numpy as np

from garage_mj.driving.difficulty.fit import DifficultyFitError, _check_out, write_records
from garage_mj.driving.difficulty.regression import (
    attainable_r,
    auc,
    bootstrap_attainable_r,
    bootstrap_r,
    pearson,
)
from garage_mj.driving.results import read_tests, rounded
from garage_mj.driving.sim.outcomes import NOT_DRIVEN
from garage_mj.scene.park_difficulty import (
    LEVEL_RANK,
    PARK_FEATURES,
    ParkDifficulty,
    ParkFeatureError,
    fit_park,
    park_features,
)

PARK_RECORD_COLUMNS = ("run", "driver", "task", "garage", "garage_hash", "test", "target_stall", "outcome", "failed",
                       "park_level", "level", *PARK_FEATURES)


def _run_rows(run: Path) -> list[dict[str, str]]:
    """A park or AVP run's rows; a one-line :class:`DifficultyFitError` for a folder that is not one."""
    if not (run / "tests.csv").is_file():
        raise DifficultyFitError(f"{run} holds no tests.csv; pass park or AVP run folders "
                                 "(garage-mj cruise --task park --out)")
    rows = read_tests(run / "tests.csv")
    if not rows:
        raise DifficultyFitError(f"{run}/tests.csv holds no test; run the park tests first (garage-mj cruise --task park)")
    cruise = [r for r in rows if r["task"] not in ("park", "avp")]
    if cruise:
        raise DifficultyFitError(f"{run} is a {cruise[0]['task']} run, not a park or AVP run; pass runs of "
                                 "garage-mj cruise --task park (or avp), or leave out --task park for a route fit")
    return rows


def read_park_runs(runs: Sequence[str | Path]) -> list[tuple[Path, list[dict[str, str]]]]:
    """Each park or AVP run of ``runs`` with its ``tests.csv`` rows; a one-line :class:`DifficultyFitError` for a
    folder that is not one."""
    return [(run, _run_rows(run)) for run in map(Path, runs)]


def load_park_runs(runs: Sequence[str | Path], features: Sequence[str] = PARK_FEATURES) -> list[dict[str, Any]]:
    """One record per driven test of the park or AVP ``runs``: its park ``features`` (default: all), level and whether
    it failed."""
    return park_records(read_park_runs(runs), features)


def park_records(read: Sequence[tuple[Path, list[dict[str, str]]]], features: Sequence[str] = PARK_FEATURES
                 ) -> list[dict[str, Any]]:
    """:func:`load_park_runs` of what :func:`read_park_runs` read."""
    out = []
    for run, rows in read:
        for row in rows:
            if row["outcome"] in NOT_DRIVEN or row["feasible"] != "1":
                continue
            try:
                feats = park_features(row, features)
            except ParkFeatureError as exc:
                raise DifficultyFitError(f"{run}: test {row['test']} of {row['garage']}: {exc} (a run of an older "
                                         "garage-mj, without the park columns: run it again into a new --out)") from None
            out.append({"run": str(run), "driver": row["driver"], "task": row["task"], "garage": row["garage"],
                        "garage_hash": row["garage_hash"], "test": int(row["test"]),
                        "target_stall": int(row["target_stall"]), "outcome": row["outcome"],
                        "failed": int(row["outcome"] != "success"), "park_level": row["park_level"],
                        "level": LEVEL_RANK[row["park_level"]], **feats})
    if not out:
        raise DifficultyFitError(f"{len(read)} park run(s) hold no driven test (every test infeasible or unproven)")
    return out


def write_park_records(path: str | Path, records: Sequence[dict[str, Any]]) -> None:
    """Park records as a fit's data file (the route fit's writer, with the park columns)."""
    write_records(path, records, PARK_RECORD_COLUMNS)


def fit_park_runs(runs: Sequence[str | Path], out: str | Path, features: Sequence[str] = PARK_FEATURES
                  ) -> tuple[ParkDifficulty, list[dict[str, Any]]]:
    """Fit a park difficulty on the driven tests of the park or AVP ``runs``; writes ``out`` and ``<out stem>.fit.csv``
    (both paths checked before the runs are read)."""
    out = Path(out)
    data = out.with_suffix(".fit.csv")
    _check_out(out, data)
    records = load_park_runs(runs, features)
    info = {"runs": [str(r) for r in runs], "drivers": sorted({r["driver"] for r in records}),
            "tasks": sorted({r["task"] for r in records}),
            "garages": len({(r["run"], r["garage_hash"]) for r in records}), "fit_data": data.name}
    try:
        model = fit_park(records, [r["failed"] for r in records], features, info=info)
    except ValueError as exc:
        raise DifficultyFitError(f"cannot fit on {len(records)} driven tests of {len(runs)} run(s): {exc}") from None
    model.fit["in_sample"] = score_park(model, records)
    out.parent.mkdir(parents=True, exist_ok=True)
    write_park_records(data, records)
    model.save(out)
    return model, records


def _measure(per_garage: Sequence[float], success: Sequence[float], per_test: Sequence[float],
             failed: Sequence[bool], seed: int) -> dict[str, Any]:
    return {"r": rounded(pearson(per_garage, success)),
            "r_ci95": [rounded(v) for v in bootstrap_r(per_garage, success, seed)],
            "auc": rounded(auc(per_test, failed))}


def score_park(model: ParkDifficulty, records: Sequence[dict[str, Any]], seed: int = 0) -> dict[str, dict[str, Any]]:
    """Per driver in ``records``: the park difficulty's and HOPE's levels' per-test AUC and per-garage r with success %
    (a garage per run; its difficulty the mean of its tests' probabilities, its level the mean of theirs)."""
    out: dict[str, dict[str, Any]] = {}
    for driver in sorted({r["driver"] for r in records}):
        recs = [r for r in records if r["driver"] == driver]
        groups: dict[tuple[str, str], list[dict[str, Any]]] = defaultdict(list)
        for r in recs:
            groups[(r["run"], r["garage_hash"])].append(r)
        rows = [groups[k] for k in sorted(groups)]
        p = np.asarray(model.test_probability(recs))
        index = {id(r): i for i, r in enumerate(recs)}
        failed = [bool(r["failed"]) for r in recs]
        success = [100.0 * (1 - np.mean([g["failed"] for g in rs])) for rs in rows]
        park = [float(np.mean([p[index[id(g)]] for g in rs])) for rs in rows]
        level = [float(np.mean([g["level"] for g in rs])) for rs in rows]
        sizes = [len(rs) for rs in rows]
        by_level = {}
        for name, rank in LEVEL_RANK.items():
            at = [r for r in recs if r["level"] == rank]
            if at:
                by_level[name] = {"tests": len(at), "success_pct": round(100.0 * (1 - np.mean([r["failed"] for r in at])), 2)}
        out[driver] = {
            "garages": len(rows), "tests": len(recs), "success_pct": round(100.0 * (1 - np.mean(failed)), 2),
            "attainable_r": rounded(attainable_r(success, sizes)),
            "attainable_r_ci95": [rounded(v) for v in bootstrap_attainable_r(success, sizes, seed)],
            "park": _measure(park, success, p.tolist(), failed, seed),
            "levels": _measure(level, success, [r["level"] for r in recs], failed, seed),
            "by_level": by_level,
        }
    return out


__all__ = ["PARK_RECORD_COLUMNS", "fit_park_runs", "load_park_runs", "park_records", "read_park_runs",
           "score_park", "write_park_records"]
