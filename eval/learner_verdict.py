"""Is the fast learner's learning quality equal to the paper learner's? Pooled over seeds, per map.

    .venv/bin/python eval/learner_verdict.py --csv docs/compare_learners.csv docs/learner_confirm.csv \
        docs/learner_confirm30.csv --json docs/learner_verdict.json

Reads the per-seed figures of ``eval/compare_dqn.py`` tables (several tables of disjoint seeds are pooled;
a learner whose settings differ between tables is refused) and checks, per map, the three criteria of the
comparison, each against the spread of the paper learner's runs, fixed before any of these runs was read:

- **garages**: the fast learner's mean number of distinct usable garages per run is at least the paper
  learner's;
- **return**: the fast learner's mean policy return (each final model at epsilon 0.05,
  ``compare_dqn.policy_eval``) is at least the paper learner's mean minus one standard deviation over its
  seeds (within its spread, or above it);
- **difficulty range**: per run, the lowest and highest difficulty among the stored garages; the fast
  learner's mean lowest is at most the paper learner's mean lowest plus one standard deviation, and its
  mean highest at least the paper learner's mean highest minus one standard deviation.

Every run counts, slow starts included: a user gets whichever run their seed gives. For the record (not a
criterion) the JSON also holds the policy return of the runs that learned to finish garages (above 0).
"""

from __future__ import annotations

import argparse
import csv
import json
from pathlib import Path

import numpy as np
from _provenance import provenance  # eval/_provenance.py: command, date, machine, commit

LEARNERS = ("paper", "fast")


def pooled(paths: list[Path]) -> dict[tuple[str, str], dict]:
    """(config, map) -> seeds and per-seed garages, policy return, training return, difficulty range."""
    out: dict[tuple[str, str], dict] = {}
    for path in paths:
        with open(path, newline="") as f:
            for row in csv.DictReader(f):
                if row["config"] not in LEARNERS:
                    continue
                key = (row["config"], row["map"])
                seeds = [int(s) for s in row["seeds"].split()]
                ranges = [tuple(float(x) for x in r.split("-")) for r in row["per_seed_difficulty_range"].split()]
                got = out.setdefault(key, {"config_json": row["config_json"], "timesteps": int(row["timesteps"]),
                                           "seeds": [], "garages": [], "policy_return": [], "return": [],
                                           "lo": [], "hi": [], "files": []})
                if got["config_json"] != row["config_json"] or got["timesteps"] != int(row["timesteps"]):
                    raise SystemExit(f"{path}: {key[0]} on {key[1]} was trained with other settings or timesteps "
                                     f"than in {got['files'][0]}; pool only tables of the same learner")
                if set(seeds) & set(got["seeds"]):
                    raise SystemExit(f"{path}: seeds {sorted(set(seeds) & set(got['seeds']))} of {key[0]} on {key[1]} "
                                     "are in an earlier table too")
                if len(ranges) != len(seeds):
                    raise SystemExit(f"{path}: {key[0]} on {key[1]} lacks a difficulty range for some seeds")
                got["seeds"] += seeds
                got["garages"] += [int(x) for x in row["per_seed_garages"].split()]
                got["policy_return"] += [float(x) for x in row["per_seed_policy_return"].split()]
                got["return"] += [float(x) for x in row["per_seed_return"].split()]
                got["lo"] += [r[0] for r in ranges]
                got["hi"] += [r[1] for r in ranges]
                got["files"].append(str(path))
    return out


def stats(values: list[float]) -> dict:
    a = np.asarray(values, dtype=float)
    return {"mean": round(float(a.mean()), 3), "sd": round(float(a.std(ddof=1)), 3) if len(a) > 1 else None,
            "min": round(float(a.min()), 3), "max": round(float(a.max()), 3)}


def verdict(paper: dict, fast: dict) -> dict:
    """The three criteria for one map (module docstring)."""
    p = {k: stats(paper[k]) for k in ("garages", "policy_return", "return", "lo", "hi")}
    f = {k: stats(fast[k]) for k in ("garages", "policy_return", "return", "lo", "hi")}
    checks = {
        "garages": f["garages"]["mean"] >= p["garages"]["mean"],
        "return": f["policy_return"]["mean"] >= p["policy_return"]["mean"] - p["policy_return"]["sd"],
        "difficulty_range": (f["lo"]["mean"] <= p["lo"]["mean"] + p["lo"]["sd"]
                             and f["hi"]["mean"] >= p["hi"]["mean"] - p["hi"]["sd"]),
    }
    # for the record, not a criterion: the runs that learned to finish garages (a policy return above 0)
    learned = {lr: stats([r for r in d["policy_return"] if r > 0]) | {"runs": sum(r > 0 for r in d["policy_return"])}
               for lr, d in (("paper", paper), ("fast", fast))}
    return {"seeds": {"paper": paper["seeds"], "fast": fast["seeds"]}, "paper": p, "fast": f,
            "policy_return_of_runs_that_learned": learned,
            "per_seed": {"paper": {k: paper[k] for k in ("garages", "policy_return")},
                         "fast": {k: fast[k] for k in ("garages", "policy_return")}},
            "checks": checks, "checks_in_words": {k: "met" if ok else "not met" for k, ok in checks.items()},
            "equal": all(checks.values())}


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--csv", type=Path, nargs="+", required=True, help="compare_dqn.py tables of disjoint seeds")
    ap.add_argument("--json", type=Path, help="also write the verdict here, with its provenance")
    args = ap.parse_args()
    data = pooled(args.csv)
    maps = sorted({m for _, m in data})
    result = {}
    print(f"{'map':<18} {'learner':<6} {'runs':>4} {'garages':>15} {'policy return':>15} {'lowest':>12} "
          f"{'highest':>12}")
    for m in maps:
        if not all((lr, m) in data for lr in LEARNERS):
            print(f"{m}: needs runs of both learners; skipped")
            continue
        v = result[m] = verdict(data[("paper", m)], data[("fast", m)])
        for lr in LEARNERS:
            s = v[lr]
            print(f"{m:<18} {lr:<6} {len(v['seeds'][lr]):>4} {s['garages']['mean']:>8,.0f} +-{s['garages']['sd']:>5,.0f} "
                  f"{s['policy_return']['mean']:>7.1f} +-{s['policy_return']['sd']:>5.1f} "
                  f"{s['lo']['mean']:>5.3f} +-{s['lo']['sd']:.3f} {s['hi']['mean']:>5.3f} +-{s['hi']['sd']:.3f}")
        print(f"{'':<18} checks: " + ", ".join(f"{k} {word}" for k, word in v["checks_in_words"].items()))
    equal = bool(result) and all(v["equal"] for v in result.values())
    print(f"equal learning quality on {', '.join(result)}: {'yes' if equal else 'no'}")
    if args.json:
        args.json.parent.mkdir(parents=True, exist_ok=True)
        args.json.write_text(json.dumps({"tables": [str(p) for p in args.csv], "maps": result, "equal": equal,
                                         "equal_in_words": "yes" if equal else "no",
                                         "provenance": provenance()}, indent=1) + "\n")
        print(f"wrote {args.json}")


if __name__ == "__main__":
    main()
