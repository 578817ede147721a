"""Which difficulties each map admits (search baseline) next to what DQN runs stored.

    .venv/bin/python eval/admissible.py [--maps NAME ...] [--evaluations 20000] [--seeds 0 1 2]
        [--libraries runs/compare_dqn/*/*/library.sqlite] [--csv docs/admissible.csv]

Per map: ``garage_mj.generation.search.search`` (MAP-Elites over difficulty bins under the painter's rules,
both ends replayed through GarageGenEnv) with each seed; the admissible range is the lowest and
highest difficulty any seed reached, and "bins" counts the 0.1-wide difficulty bins it reached.
Search gives a lower bound on the true range. The DQN columns read every garage of the map in
the given libraries (unconditioned DQN runs). Prints a Markdown table and writes the CSV.
"""

from __future__ import annotations

import argparse
import csv
import time
from pathlib import Path

from garage_mj.generation.library import Library
from garage_mj.generation.search import BIN_WIDTH, search
from garage_mj.grid.map_io import list_maps

N_BINS = round(1 / BIN_WIDTH)


def _bins(values) -> set[int]:
    return {min(int(v / BIN_WIDTH), N_BINS - 1) for v in values}


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--maps", nargs="+", default=[m.name for m in list_maps()])
    ap.add_argument("--evaluations", type=int, default=20_000)
    ap.add_argument("--seeds", nargs="+", type=int, default=[0, 1, 2])
    ap.add_argument("--libraries", nargs="*", type=Path, default=[])
    ap.add_argument("--csv", type=Path, default=Path("docs/admissible.csv"))
    args = ap.parse_args()
    rows = []
    for name in args.maps:
        t0 = time.perf_counter()
        results = [search(name, args.evaluations, seed=s) for s in args.seeds]
        lo = min(r.range[0] for r in results)
        hi = max(r.range[1] for r in results)
        bins = set().union(*(set(r.bins_reached()) for r in results))
        row = {"map": name, "search_evaluations": args.evaluations, "search_seeds": len(args.seeds),
               "search_s": round(time.perf_counter() - t0, 1),
               "admissible_lo": round(lo, 3), "admissible_hi": round(hi, 3), "admissible_bins": len(bins),
               "dqn_garages": 0, "dqn_lo": "", "dqn_hi": "", "dqn_bins": ""}
        diffs = []
        for lib_path in args.libraries:
            with Library(lib_path, create=False) as lib:
                diffs += [r.difficulty for r in lib.query(map=name)]
        if diffs:
            row.update(dqn_garages=len(diffs), dqn_lo=round(min(diffs), 3), dqn_hi=round(max(diffs), 3),
                       dqn_bins=len(_bins(diffs)))
        rows.append(row)
        print(f"{name}: search {lo:.3f}-{hi:.3f} ({len(bins)} bins, {row['search_s']} s), "
              f"DQN {row['dqn_lo']}-{row['dqn_hi']} ({len(diffs)} garages)", flush=True)
    args.csv.parent.mkdir(parents=True, exist_ok=True)
    with open(args.csv, "w", newline="") as f:
        w = csv.DictWriter(f, fieldnames=list(rows[0]))
        w.writeheader()
        w.writerows(rows)
    print("\n| map | admissible range (search) | bins reached | unconditioned DQN range | DQN bins filled | DQN garages |")
    print("|---|---|---|---|---|---|")
    for r in rows:
        dqn = f"{r['dqn_lo']:.2f}-{r['dqn_hi']:.2f}" if r["dqn_garages"] else "not run"
        print(f"| {r['map']} | {r['admissible_lo']:.2f}-{r['admissible_hi']:.2f} | {r['admissible_bins']} of {N_BINS} "
              f"| {dqn} | {r['dqn_bins'] if r['dqn_garages'] else '-'} | {r['dqn_garages']} |")
    print(f"wrote {args.csv}")


if __name__ == "__main__":
    main()
