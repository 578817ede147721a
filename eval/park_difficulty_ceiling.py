"""How well could any model of the park features predict a driver's park failures? A ceiling for the park difficulty.

    .venv/bin/python eval/park_difficulty_ceiling.py RUN [RUN ...] [--only static|actors] [--behaviours] [--folds 5]
        [--repeats 3] [--json OUT.json]

Reads the park tests of the park runs ``RUN`` (folders holding a ``tests.csv``, or folders of such folders, e.g. the
run folders of ``eval/bench_learned_park.py``) as ``garage-mj difficulty fit --task park`` reads them: each driven
test's :data:`~garage_mj.scene.park_difficulty.PARK_FEATURES` (what is known before the drive) and whether it failed
(``--only``: the tests without actors, or with them). Scores, per test (AUC of failure):

- the park difficulty under the driver's park model as shipped (fitted on other garages);
- cross-validated on these tests themselves, folds by garage (no garage in both the fitting and the scored part),
  ``--repeats`` shufflings of the garages into ``--folds`` folds: the park difficulty's own model refitted
  (:func:`~garage_mj.scene.park_difficulty.fit_park`: logistic, every weight >= 0), a logistic regression with free
  signs, and two flexible models of the same features (scikit-learn's gradient-boosted trees and random forest).

If the flexible models, fitted on the very tests they are scored on (held-out folds aside), reach no higher AUC than
the shipped model, the features, not the model's form, bound what a park difficulty can predict for this driver.

The base models leave out the pedestrians' behaviours (crossing behind the stall, walking beside it: park features
too, ``behind_stall`` and ``beside_stall``). ``--behaviours`` adds them: the two free-form models and the park
difficulty's own form are also cross-validated with these counts as two more features. A run's ``tests.csv`` records
them; a run of an older garage-mj does not, and each of its tests with actors is drawn again (its run's settings and
garage, its seed: the env's reset, nothing driven) to count them, with ``--behaviours`` or where a driver's shipped
park model reads them. Writes the figures and the provenance to ``--json``.
"""

from __future__ import annotations

import argparse
import json
from pathlib import Path

import numpy as np
from _provenance import provenance  # eval/_provenance.py: command, date, machine, commit

from garage_mj.core.fsutil import write_json
from garage_mj.driving.difficulty.fit import DifficultyFitError
from garage_mj.driving.difficulty.park import park_records, read_park_runs
from garage_mj.driving.difficulty.park_rating import choose_park_model
from garage_mj.driving.difficulty.regression import auc
from garage_mj.scene.park_difficulty import PARK_FEATURES, fit_park

BEHAVIOURS = ("behind_stall", "beside_stall")  # the pedestrians' park behaviours (garage_mj.scene.actor_spec)
#: the park features but the pedestrians' behaviours (park features too, of the same names), the base models' features
BASE_FEATURES = tuple(f for f in PARK_FEATURES if f not in BEHAVIOURS)


def pedestrian_behaviours(run: Path, records: list[dict]) -> dict[tuple[str, int], dict[str, int]]:
    """Per test (garage hash, index) of ``records`` (tests of the run folder ``run`` with actors), its pedestrians by behaviour:
    the test drawn again by the run's env (its ``run.json`` settings, its ``garages.json``, the test's seed), nothing
    driven."""
    from garage_mj.driving.episode import cached_env, close_cached_env
    from garage_mj.driving.garage_set import load_garage_set
    from garage_mj.driving.sources import CruiseSettings, cruise_seed

    settings = CruiseSettings.from_stored(json.loads((run / "run.json").read_text()))
    sources = {s.hash: s for s in load_garage_set(str(run / "garages.json"))}
    out = {}
    for r in records:
        env = cached_env(sources[r["garage_hash"]], settings)
        env.reset(seed=cruise_seed(settings.seed, r["garage_hash"], r["test"]))
        kinds = [a.behaviour for a in env.scenario.actors if a.kind == "pedestrian"]
        out[r["garage_hash"], r["test"]] = {b: kinds.count(b) for b in BEHAVIOURS}
    close_cached_env()
    return out


def read_tests(runs: list[Path], only: str | None = None, behaviours: bool = False) -> list[dict]:
    """The driven park tests of ``runs`` (a run folder or a folder of run folders) as
    :func:`~garage_mj.driving.difficulty.park.load_park_runs` reads them, each rated under its driver's park model
    as shipped (``only``: ``"static"`` or ``"actors"``, the tests without or with actors), with their pedestrians by
    behaviour: as ``tests.csv`` records them, or for a run of an older garage-mj drawn again
    (:func:`pedestrian_behaviours`) when ``behaviours`` asks for them or a driver's park model reads them."""
    folders = []
    for run in runs:
        folders += [run] if (run / "tests.csv").is_file() else sorted(p.parent for p in run.glob("*/tests.csv"))
    if not folders:
        raise SystemExit(f"no tests.csv in {', '.join(map(str, runs))}: give park run folders")
    rows = []
    for folder in folders:
        read = read_park_runs([folder])
        try:  # a run that records its pedestrians' behaviours: every park feature
            records, recorded = park_records(read), True
        except DifficultyFitError:  # a run of an older garage-mj: the others, the behaviours drawn again if wanted
            records, recorded = park_records(read, BASE_FEATURES), False
        records = [r for r in records if only is None or (r["actors"] > 0) == (only == "actors")]
        models = {d: choose_park_model(True, d).model for d in {r["driver"] for r in records}}
        rated_needs = any(set(BEHAVIOURS) & set(m.features) for m in models.values())
        drawn = {} if recorded or not (behaviours or rated_needs) else \
            pedestrian_behaviours(folder, [r for r in records if r["actors"] > 0])
        for r in records:
            features = {k: r[k] for k in BASE_FEATURES}
            walking = {b: r[b] for b in BEHAVIOURS} if recorded else \
                drawn.get((r["garage_hash"], r["test"]), dict.fromkeys(BEHAVIOURS, 0))  # no actors: none walk
            rows.append({"features": features, "failed": bool(r["failed"]), "garage": r["garage_hash"],
                         "rated": float(models[r["driver"]].test_probability({**features, **walking})),
                         "behaviours": walking})
    return rows


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("runs", nargs="+", type=Path, help="park run folders (or folders of them)")
    ap.add_argument("--only", choices=("static", "actors"), help="only the tests without (static) or with actors")
    ap.add_argument("--behaviours", action="store_true",
                    help="also with the pedestrians' behaviours as features (an older run's tests with actors drawn again)")
    ap.add_argument("--folds", type=int, default=5)
    ap.add_argument("--repeats", type=int, default=3)
    ap.add_argument("--json", type=Path)
    args = ap.parse_args(argv)
    try:
        from sklearn.ensemble import HistGradientBoostingClassifier, RandomForestClassifier
        from sklearn.linear_model import LogisticRegression
        from sklearn.model_selection import GroupKFold
        from sklearn.pipeline import make_pipeline
        from sklearn.preprocessing import StandardScaler
    except ImportError:
        raise SystemExit("this benchmark needs scikit-learn: make install (or pip install -e '.[dev]')") from None
    prov = provenance(argv)
    rows = read_tests(args.runs, args.only, args.behaviours)
    X = np.array([[r["features"][k] for k in BASE_FEATURES] for r in rows])
    B = np.array([[r["behaviours"][b] for b in BEHAVIOURS] for r in rows], dtype=float)
    y = np.array([r["failed"] for r in rows], dtype=bool)
    groups = np.array([r["garage"] for r in rows])

    def park_model(train: np.ndarray, test: np.ndarray) -> np.ndarray:
        m = fit_park([rows[i]["features"] for i in train], y[train].tolist(), BASE_FEATURES)
        return np.array([m.test_probability(rows[i]["features"]) for i in test])

    def park_model_behaviours(train: np.ndarray, test: np.ndarray) -> np.ndarray:
        """The park difficulty's form (weights >= 0) with the pedestrians' behaviour counts as two more features."""
        from garage_mj.scene.route_difficulty import fit

        feats = [{**rows[i]["features"], **rows[i]["behaviours"]} for i in range(len(rows))]
        m = fit([feats[i] for i in train], y[train].tolist(), (*BASE_FEATURES, *BEHAVIOURS))
        return np.array([m.test_probability(feats[i]) for i in test])

    def sklearn_model(make, with_behaviours: bool = False):
        data = np.hstack([X, B]) if with_behaviours else X

        def run(train: np.ndarray, test: np.ndarray) -> np.ndarray:
            m = make()
            m.fit(data[train], y[train])
            return m.predict_proba(data[test])[:, 1]
        return run

    models = {
        "park difficulty, refitted (logistic, weights >= 0)": park_model,
        "logistic regression, free signs": sklearn_model(
            lambda: make_pipeline(StandardScaler(), LogisticRegression(max_iter=1000))),
        "gradient-boosted trees": sklearn_model(
            lambda: HistGradientBoostingClassifier(max_depth=3, learning_rate=0.05, max_iter=200, random_state=0)),
        "random forest": sklearn_model(
            lambda: RandomForestClassifier(n_estimators=300, min_samples_leaf=5, random_state=0)),
    }
    if args.behaviours:
        models.update({
            "park difficulty's form + pedestrians' behaviours": park_model_behaviours,
            "logistic regression, free signs + behaviours": sklearn_model(
                lambda: make_pipeline(StandardScaler(), LogisticRegression(max_iter=1000)), True),
            "random forest + behaviours": sklearn_model(
                lambda: RandomForestClassifier(n_estimators=300, min_samples_leaf=5, random_state=0), True),
        })
    cv = {}
    for name, run in models.items():
        aucs = []
        for rep in range(args.repeats):
            pred = np.zeros(len(y))
            for train, test in GroupKFold(args.folds, shuffle=True, random_state=rep).split(X, y, groups):
                pred[test] = run(train, test)
            aucs.append(auc(pred.tolist(), y.tolist()))
        cv[name] = {"auc_per_repeat": [round(a, 4) for a in aucs], "auc_mean": round(float(np.mean(aucs)), 4)}
        print(f"{name:52s} grouped {args.folds}-fold CV AUC {np.mean(aucs):.3f} ({', '.join(f'{a:.3f}' for a in aucs)})",
              flush=True)
    rated = auc([r["rated"] for r in rows], y.tolist())
    out = {"runs": [str(r) for r in args.runs], "only": args.only, "behaviours": args.behaviours, "tests": len(rows), "garages": int(len(np.unique(groups))),
           "failed_pct": round(100 * float(y.mean()), 1), "features": list(BASE_FEATURES),
           "rated_auc": round(rated, 4), "folds": args.folds, "repeats": args.repeats, "cross_validated": cv,
           "best_cross_validated_auc": max(v["auc_mean"] for v in cv.values()), "provenance": prov}
    if args.json:
        args.json.parent.mkdir(parents=True, exist_ok=True)
        write_json(args.json, out, indent=1)
    print(f"{'the park difficulty as rated (the shipped model)':52s} AUC {rated:.3f} over {len(rows)} tests, "
          f"{len(np.unique(groups))} garages, {y.mean():.1%} failed")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
