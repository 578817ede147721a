"""The route-difficulty generation target: ``generate --metric route`` fills every route-difficulty bin a map admits.

Per 13x13 map: which bins of width 0.1 the map admits is estimated from the route difficulty of
``--sample`` garages of ``--library`` (stratified by the paper's difficulty, seeded) and from what
the generate calls themselves reach; then, for every bin from the lowest to the highest admitted
one, ``generate --metric route --count 20`` runs into a fresh library with a CPU-time budget of
``--max-cpu`` seconds (``time.process_time``, one process). Prints per bin the garages found and
the CPU seconds, and writes them as JSON. Maps run in parallel (``--workers``), each in its own process.

    .venv/bin/python eval/bench_generate_route.py --library runs/paper_10pct/library.sqlite \\
        --workers 2 --json docs/route_difficulty/bench_generate_route.json
"""

from __future__ import annotations

import argparse
import json
import sys
import tempfile
import time
from concurrent.futures import ProcessPoolExecutor
from pathlib import Path

from _provenance import provenance  # eval/_provenance.py: command, date, machine, commit

MAPS = ("m4_13x13_offset", "m5_13x13_aligned", "m6_13x13_s", "m7_13x13_u")
BIN = 0.1


def _sample_range(library: Path | None, map_name: str, n: int) -> list[float]:
    """Route difficulties of ``n`` library garages of the map (none without a library)."""
    if library is None or n == 0:
        return []
    from garage_mj.driving.garage_set import GarageSet
    from garage_mj.scene.route_difficulty import load_route_model, route_difficulty

    model = load_route_model()
    values = [route_difficulty(s.garage, model) for s in GarageSet.from_library(library, map=map_name, n=n, seed=0)]
    return [v for v in values if v == v]


def bench_map(map_name: str, library: Path | None, sample: int, count: int, max_cpu: float, seed: int) -> dict:
    from garage_mj.generation.conditioned import GenerationError
    from garage_mj.generation.generator import RouteMetric, generate
    from garage_mj.scene.route_difficulty import load_route_model, route_difficulty

    model = load_route_model()
    metric = RouteMetric(lambda g: route_difficulty(g, model), model.key)
    t0 = time.process_time()
    seen = _sample_range(library, map_name, sample)
    sample_cpu = time.process_time() - t0
    bins = sorted({min(int(v / BIN), round(1 / BIN) - 1) for v in seen})
    lo, hi = (bins[0], bins[-1]) if bins else (0, round(1 / BIN) - 1)
    rows = []
    k = lo
    while k <= hi:
        band = (round(k * BIN, 3), round((k + 1) * BIN, 3))
        with tempfile.TemporaryDirectory() as tmp:
            c0 = time.process_time()
            try:
                r = generate(map_name, band, count, Path(tmp) / "lib.sqlite", seed=seed, max_seconds=max_cpu,
                             max_episodes=10**9,  # the CPU time is the budget
                             clock=time.process_time, progress=False, route=metric)
            except GenerationError as exc:
                r = exc.result
            cpu = time.process_time() - c0
        found = r.found if r is not None else 0
        values = r.difficulties if r is not None else []
        rows.append({"bin": list(band), "found": found, "cpu_s": round(cpu, 1), "episodes": r.episodes if r else 0,
                     "search_steps": r.search_steps if r else 0, "filled": found >= count})
        print(f"{map_name} route difficulty {band[0]:.1f}-{band[1]:.1f}: {found}/{count} in {cpu:.1f} CPU-s",
              flush=True)
        # a bin the sample did not show but generate reached widens the admitted range
        for v in values:
            b = min(int(v / BIN), round(1 / BIN) - 1)
            lo, hi = min(lo, b), max(hi, b)
        k += 1
    return {"map": map_name, "sample": len(seen), "sample_cpu_s": round(sample_cpu, 1),
            "sample_range": [round(min(seen), 3), round(max(seen), 3)] if seen else None, "bins": rows}


def main(argv: list[str] | None = None) -> int:
    from garage_mj.cli._common import positive_int

    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--library", type=Path, help="DQN library whose garages show each map's range")
    p.add_argument("--sample", type=int, default=100, help="library garages rated per map (default 100)")
    p.add_argument("--maps", default=",".join(MAPS))
    p.add_argument("--count", type=positive_int, default=20)
    p.add_argument("--max-cpu", type=float, default=60.0, help="CPU seconds per bin (default 60)")
    p.add_argument("--seed", type=int, default=0)
    p.add_argument("--workers", type=positive_int, default=1)
    p.add_argument("--json", type=Path)
    args = p.parse_args(argv)
    prov = provenance(argv)  # before the run: the load it starts at
    maps = args.maps.split(",")
    jobs = [(m, args.library, args.sample, args.count, args.max_cpu, args.seed) for m in maps]
    if args.workers > 1:
        with ProcessPoolExecutor(args.workers) as ex:
            results = list(ex.map(bench_map, *zip(*jobs, strict=True)))
    else:
        results = [bench_map(*j) for j in jobs]
    print("\nmap                admitted bins (as far as seen)   filled with 20   worst CPU-s of a filled bin")
    for r in results:
        filled = [b for b in r["bins"] if b["filled"]]
        worst = max((b["cpu_s"] for b in filled), default=float("nan"))
        print(f"{r['map']:<18} {len(r['bins']):>3}                             {len(filled):>3}            {worst:.1f}")
    if args.json:
        args.json.parent.mkdir(parents=True, exist_ok=True)
        args.json.write_text(json.dumps({"count": args.count, "max_cpu_s": args.max_cpu, "maps": results,
                                          "provenance": prov}, indent=1)
                             + "\n")
        print(f"wrote {args.json}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
