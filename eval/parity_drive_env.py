"""Parity of the drive env across a change: the same fixed tests, outcome by outcome, before and after.

Two fixed sets (a faster env must keep the outcomes):

- ``vision``: 500 tests of the ``vision`` driver with continuous actions (its declared type), 10
  ``m5_13x13_aligned`` garages painted by ``painted_sources("m5_13x13_aligned", 10, seed=0)`` x 50
  tests, run seed 0, occupancy 0.5;
- ``oracle``: the ``eval/bench_drivable.py`` set with its defaults: every shipped map, 20 painted
  garages x 10 tests (seed 0), plus the hand-made shapes of ``tests/data/shapes``, ``oracle`` with
  continuous actions.

``run`` drives them with the code this interpreter imports (point ``PYTHONPATH`` at another tree to
record that tree) into ``OUT/vision`` and ``OUT/oracle`` (ordinary cruise folders, resumable);
``compare`` matches two such records test by test on (garage hash, test index) and lists every test
whose outcome changed, and how many end at the same simulated time and path length (the rows' 1 ms and
1 mm resolution) having hit the same geom. ``missed_goal`` (once counted as ``deadlock``) is compared
as ``deadlock``, so a record made before the split compares with one made after it.

    PYTHONPATH=/tmp/before_speed .venv/bin/python eval/parity_drive_env.py run --out /tmp/before_speed_rows
    .venv/bin/python eval/parity_drive_env.py run --out runs/parity_after
    .venv/bin/python eval/parity_drive_env.py compare /tmp/before_speed_rows runs/parity_after \\
        --json docs/parity_drive_env.json
"""

from __future__ import annotations

import argparse
import csv
import json
import sys
import time
from pathlib import Path

VISION_MAP = "m5_13x13_aligned"
VISION_GARAGES = 10
VISION_TESTS = 50
ORACLE_GARAGES = 20  # per shipped map, as eval/bench_drivable.py
ORACLE_TESTS = 10
SEED = 0
#: Outcome kinds compared as one: missed_goal was part of deadlock before it had a class of its own.
SAME_AS = {"missed_goal": "deadlock"}


def _shape_sources(root: Path):
    from garage_mj.driving.sources import CruiseSource
    from garage_mj.grid.garage import Garage

    return [CruiseSource.from_garage(Garage.from_json(p.read_text()), p.stem)
            for p in sorted((root / "tests" / "data" / "shapes").glob("*.json"))]


def run(out: Path, workers: int, parts: list[str]) -> None:
    """Drive the fixed sets with the imported garage_mj into ``out/<part>``."""
    import garage_mj
    from garage_mj import list_maps
    from garage_mj.core.backends import Compute
    from garage_mj.driving.cruise import run_cruise
    from garage_mj.driving.sources import CruiseSettings, painted_sources

    tree = Path(garage_mj.__file__).resolve().parent.parent
    print(f"garage_mj from {tree}", flush=True)
    if "vision" in parts:
        t0 = time.perf_counter()
        res = run_cruise(painted_sources(VISION_MAP, VISION_GARAGES, seed=SEED), VISION_TESTS,
                         CruiseSettings("vision", seed=SEED, action_type="continuous"), out / "vision",
                         compute=Compute(workers=workers, progress=False))
        print(f"vision: {res.stats['tests']} tests, success {res.stats['success_pct']}%, failures "
              f"{res.stats['failures']}, {time.perf_counter() - t0:.0f} s", flush=True)
    if "oracle" in parts:
        sources = [s for m in list_maps() for s in painted_sources(m.name, ORACLE_GARAGES, seed=SEED)]
        sources += _shape_sources(tree)
        t0 = time.perf_counter()
        res = run_cruise(sources, ORACLE_TESTS, CruiseSettings("oracle", seed=SEED, action_type="continuous"),
                         out / "oracle", compute=Compute(workers=workers, progress=False))
        print(f"oracle: {res.stats['tests']} tests, {res.stats['infeasible']} infeasible, success "
              f"{res.stats['success_pct']}% of feasible, failures {res.stats['failures']}, "
              f"{time.perf_counter() - t0:.0f} s", flush=True)


def _rows(folder: Path) -> dict[tuple[str, int], dict[str, str]]:
    with open(folder / "tests.csv", newline="") as f:
        return {(r["garage_hash"], int(r["test"])): r for r in csv.DictReader(f)}


def _kind(row: dict[str, str]) -> str:
    return SAME_AS.get(row["outcome"], row["outcome"])


def compare_part(before: Path, after: Path) -> dict:
    """Outcome changes between two records of one set."""
    a, b = _rows(before), _rows(after)
    if a.keys() != b.keys():
        raise SystemExit(f"{before} and {after} hold different tests ({len(a)} and {len(b)}); run both to the end")
    changed = []
    for key in sorted(a):
        ra, rb = a[key], b[key]
        if _kind(ra) != _kind(rb):
            changed.append({"garage": ra["garage"], "test": key[1], "seed": int(ra["seed"]),
                            "before": ra["outcome"], "after": rb["outcome"],
                            "before_reason": ra["reason"], "after_reason": rb["reason"]})
    def tally(rows):
        out: dict[str, int] = {}
        for r in rows.values():
            out[r["outcome"]] = out.get(r["outcome"], 0) + 1
        return dict(sorted(out.items()))

    def success(rows):
        feas = [r for r in rows.values() if r["outcome"] != "infeasible"]
        return round(100 * sum(r["outcome"] == "success" for r in feas) / max(len(feas), 1), 2), len(feas)

    (sb, fb), (sa, fa) = success(a), success(b)
    same_drive = sum(all(a[k][c] == b[k][c] for c in ("time", "path_length", "hit_geom")) for k in a)
    return {"tests": len(a), "changed": len(changed), "same_pct": round(100 * (len(a) - len(changed)) / len(a), 2),
            "same_end_time_path_and_hit": same_drive,
            "before": tally(a), "after": tally(b), "success_pct_of_feasible": {"before": sb, "after": sa},
            "feasible": {"before": fb, "after": fa}, "changes": changed}


def compare(before: Path, after: Path) -> dict:
    out = {"compared_as_one": SAME_AS}
    for part in ("vision", "oracle"):
        if (before / part / "tests.csv").is_file() and (after / part / "tests.csv").is_file():
            out[part] = compare_part(before / part, after / part)
    return out


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    sub = ap.add_subparsers(dest="cmd", required=True)
    r = sub.add_parser("run", help="drive the fixed sets with the imported code")
    r.add_argument("--out", type=Path, required=True)
    r.add_argument("--workers", type=int, default=1)
    r.add_argument("--parts", nargs="*", default=["vision", "oracle"], choices=["vision", "oracle"])
    c = sub.add_parser("compare", help="outcome changes between two records")
    c.add_argument("before", type=Path)
    c.add_argument("after", type=Path)
    c.add_argument("--json", type=Path, default=None, help="also write the comparison here")
    args = ap.parse_args(argv)
    if args.cmd == "run":
        run(args.out, args.workers, args.parts)
        return 0
    result = compare(args.before, args.after)
    for part in ("vision", "oracle"):
        if part not in result:
            continue
        p = result[part]
        print(f"{part}: {p['tests']} tests, {p['changed']} changed ({p['same_pct']}% the same; "
              f"{p['same_end_time_path_and_hit']} end at the same time [ms] and path length [mm], hitting the same "
              f"geom); success of feasible {p['success_pct_of_feasible']['before']}% -> "
              f"{p['success_pct_of_feasible']['after']}%")
        print(f"  before {p['before']}\n  after  {p['after']}")
        for ch in p["changes"]:
            print(f"  {ch['garage']} test {ch['test']}: {ch['before']} -> {ch['after']} ({ch['after_reason']})")
    if args.json:
        args.json.parent.mkdir(parents=True, exist_ok=True)
        args.json.write_text(json.dumps(result, indent=2) + "\n")
    return 0


if __name__ == "__main__":
    sys.exit(main())
