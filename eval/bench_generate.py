"""How many distinct garages ``garage-mj generate`` finds per 0.1-wide difficulty bin, and how fast.

    .venv/bin/python eval/bench_generate.py [--maps m4_13x13_offset ...] [--count 20] [--seconds 60]
        [--seconds-unreached 60] [--seed 0] [--search-evaluations 10000] [--csv docs/bench_generate.csv]
        [--no-search] [--resume]

Per map (default: the shipped 13x13 maps) and bin [b/10, (b+1)/10]: ``garage_mj.generation.generator.generate``
with the shipped generator, asking for ``--count`` garages with at most ``--seconds`` of CPU time
of rollouts and search (``--seconds-unreached`` in bins the search reached no garage in; one process, torch on one thread; CPU time, since the machine is shared and wall
time depends on the other jobs) into a throw-away library; the row records garages found (and how
many came from the policy's rollouts and from the search stage), episodes, search steps, replays,
CPU seconds and wall seconds. The CSV is rewritten after every bin; ``--resume`` keeps the rows of
an existing CSV and runs only the missing bins. ``garage_mj.generation.search.search`` tells which bins the map admits (search reached
a garage there; a lower bound, so an "unreached" bin may still be admissible). Prints a Markdown
table per map and a summary line, and writes the CSV.
"""

from __future__ import annotations

import argparse
import csv
import tempfile
import time
from pathlib import Path

from garage_mj.generation.generator import GenerationError, generate
from garage_mj.generation.search import search

MAPS = ["m4_13x13_offset", "m5_13x13_aligned", "m6_13x13_s", "m7_13x13_u"]
N_BINS = 10
FIELDS = ["map", "bin", "admissible", "found", "found_policy", "found_search", "episodes", "search_steps", "replays",
          "cpu_s", "wall_s", "filled"]


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--maps", nargs="+", default=MAPS)
    ap.add_argument("--count", type=int, default=20)
    ap.add_argument("--seconds", type=float, default=60.0, help="CPU seconds per bin the search reached")
    ap.add_argument("--seconds-unreached", type=float, default=60.0, help="CPU seconds per other bin")
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--search-evaluations", type=int, default=10_000)
    ap.add_argument("--csv", type=Path, default=Path("docs/bench_generate.csv"))
    ap.add_argument("--no-search", action="store_true", help="policy rollouts only (generate --no-search)")
    ap.add_argument("--resume", action="store_true", help="keep the rows of an existing --csv, run the missing bins")
    args = ap.parse_args()
    rows: list[dict] = []
    if args.resume and args.csv.is_file():
        with open(args.csv, newline="") as f:
            rows = [r for r in csv.DictReader(f) if r["map"] in args.maps]
        for r in rows:
            for k in ("admissible", "filled"):
                r[k] = r[k] == "True"
    done = {(r["map"], r["bin"]) for r in rows}

    def write() -> None:
        args.csv.parent.mkdir(parents=True, exist_ok=True)
        with open(args.csv, "w", newline="") as f:
            w = csv.DictWriter(f, fieldnames=FIELDS)
            w.writeheader()
            w.writerows(sorted(rows, key=lambda r: (args.maps.index(r["map"]), r["bin"])))

    for name in args.maps:
        if all((name, f"{b / N_BINS:.1f}-{(b + 1) / N_BINS:.1f}") in done for b in range(N_BINS)):
            continue
        admitted = set(search(name, args.search_evaluations, seed=0).bins_reached())
        with tempfile.TemporaryDirectory() as tmp:
            for b in range(N_BINS):
                lo, hi = b / N_BINS, (b + 1) / N_BINS
                if (name, f"{lo:.1f}-{hi:.1f}") in done:
                    continue
                t0 = time.perf_counter()
                try:
                    r = generate(name, (lo, hi), args.count, Path(tmp) / f"bin{b}.sqlite", seed=args.seed,
                                 max_episodes=10**9, max_seconds=args.seconds if b in admitted else args.seconds_unreached,
                                 clock=time.process_time, progress=False, search=not args.no_search)
                except GenerationError as exc:
                    r = exc.result
                    if r is None:
                        raise
                wall = time.perf_counter() - t0
                row = {"map": name, "bin": f"{lo:.1f}-{hi:.1f}", "admissible": b in admitted, "found": r.found,
                       "found_policy": r.found_policy, "found_search": r.found_search, "episodes": r.episodes,
                       "search_steps": r.search_steps, "replays": r.replays, "cpu_s": round(r.cpu_seconds, 1),
                       "wall_s": round(wall, 1), "filled": r.found >= args.count}
                rows.append(row)
                write()
                print(f"{name} {row['bin']}: {r.found} garages ({r.found_policy} policy, {r.found_search} search), "
                      f"{r.episodes} episodes, {r.search_steps} search steps, {r.cpu_seconds:.1f} CPU s"
                      f"{'' if b in admitted else ' (search reached no garage here)'}", flush=True)
    write()
    rows.sort(key=lambda r: (args.maps.index(r["map"]), r["bin"]))
    print(f"\n| map | bin | search reached | garages found (of {args.count}) | policy | search | episodes "
          "| search steps | CPU s |")
    print("|---|---|---|---|---|---|---|---|---|")
    for r in rows:
        print(f"| {r['map']} | {r['bin']} | {'yes' if r['admissible'] else 'no'} | {r['found']} | {r['found_policy']} "
              f"| {r['found_search']} | {r['episodes']} | {r['search_steps']} | {r['cpu_s']} |")
    print("\n| map | admissible bins (search) | of them filled | bins filled in all |")
    print("|---|---|---|---|")
    for name in args.maps:
        mine = [r for r in rows if r["map"] == name]
        print(f"| {name} | {sum(r['admissible'] for r in mine)} | {sum(r['filled'] and r['admissible'] for r in mine)} "
              f"| {sum(r['filled'] for r in mine)} |")
    print(f"wrote {args.csv}")


if __name__ == "__main__":
    main()
