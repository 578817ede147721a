"""How many park-difficulty bands ``garage-mj generate --metric park`` fills per 13x13 map and park geometry.

    nice -n 10 .venv/bin/python eval/bench_generate_park.py [--maps m4_13x13_offset ...] [--count 2]
        [--seconds 10] [--seed 0] [--json docs/bench_generate_park.json]

Per map (default: the shipped 13x13 maps), park geometry (``default``, and ``tight``: stall width 2.3 m, aisle width
6.5 m) and band [b/5, (b+1)/5] of the park difficulty (``--park-model``, default the shipped ``park_assist`` model; the
learned parking driver's: ``learned_park``): one call of
``garage_mj.generation.generator.generate`` with ``garage_mj.scene.park_rating.ParkRater`` as its metric (what
``garage-mj generate --metric park`` runs), asking for ``--count`` garages within ``--seconds`` of wall time into a
throw-away library (``--seconds 0``: no time limit, the default episode budget of ``generate`` alone, as the
command runs without ``--max-seconds``). A band is filled when the call finds ``--count``. Each row records the
garages found, the garages rated and the CPU seconds the ratings took (so the seconds per rating), the unbuildable garages and the
values found. Writes the JSON with the figures per map and geometry and the provenance; prints one line per call.

With ``--search NAMES`` (named park geometries, comma-separated) each map and band is instead one call of
``garage_mj.scene.park_rating.generate_in_geometries`` over those geometries (what ``garage-mj generate --metric park
--geometries NAMES`` runs), ``--seconds`` for the whole call, probes included; the JSON then holds per map the bands
filled and, per band, the geometry each garage was found in:

    nice -n 10 .venv/bin/python eval/bench_generate_park.py --search default,tight,angled60,parallel \
        --json docs/bench_generate_park_search.json
"""

from __future__ import annotations

import argparse
import tempfile
import time
from pathlib import Path

from _provenance import provenance  # eval/_provenance.py: command, date, machine, commit

from garage_mj.core.fsutil import write_json
from garage_mj.driving.park_geometries import PARK_GEOMETRIES
from garage_mj.generation.generator import GenerationError, RouteMetric, generate
from garage_mj.scene.park_difficulty import DEFAULT_PARK_MODEL, SHIPPED_PARK_MODELS, load_park_model
from garage_mj.scene.park_rating import ParkRater, generate_in_geometries
from garage_mj.scene.world import geometry, world_with

MAPS = ["m4_13x13_offset", "m5_13x13_aligned", "m6_13x13_s", "m7_13x13_u"]
GEOMETRIES = {"default": {}, "tight": {"stall_width": 2.3, "aisle_width": 6.5}}
N_BANDS = 5


class _Timed:
    """A rater that adds up the CPU time of its calls and keeps the values it gave."""

    def __init__(self, rater: ParkRater) -> None:
        self.rater, self.cpu_s, self.values = rater, 0.0, []

    def __call__(self, garage):
        t = time.process_time()
        value = self.rater(garage)
        self.cpu_s += time.process_time() - t
        if value == value:
            self.values.append(value)
        return value


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--maps", nargs="+", default=MAPS)
    ap.add_argument("--geometries", nargs="+", default=list(GEOMETRIES), choices=list(GEOMETRIES))
    ap.add_argument("--count", type=int, default=2)
    ap.add_argument("--seconds", type=float, default=10.0,
                    help="wall seconds per band (generate's --max-seconds); 0: none, generate's default episode budget "
                         "alone (what the command does without --max-seconds)")
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--json", type=Path, default=Path("docs/bench_generate_park.json"))
    ap.add_argument("--search", metavar="NAMES", help="named park geometries searched by one call per band")
    ap.add_argument("--park-model", default=DEFAULT_PARK_MODEL,
                    help=f"the park difficulty: a shipped model's name ({', '.join(SHIPPED_PARK_MODELS)}) or a model "
                         f"file (default {DEFAULT_PARK_MODEL})")
    args = ap.parse_args()
    args.model = load_park_model(args.park_model)
    if args.seconds <= 0:
        args.seconds = None
    if args.search:
        return searched(args, [n.strip() for n in args.search.split(",") if n.strip()])
    rows, summary = [], []
    t_all = time.perf_counter()
    with tempfile.TemporaryDirectory() as tmp:
        for geo_name in args.geometries:
            world = world_with(GEOMETRIES[geo_name])
            for map_name in args.maps:
                filled = []
                for b in range(N_BANDS):
                    band = (b / N_BANDS, (b + 1) / N_BANDS)
                    rater = ParkRater(world, model=args.model, seed=args.seed)
                    timed = _Timed(rater)
                    metric = RouteMetric(timed, rater.key, "park difficulty")
                    lib = Path(tmp) / f"{geo_name}_{map_name}_{b}.sqlite"
                    try:
                        r = generate(map_name, band, args.count, lib, seed=args.seed, max_seconds=args.seconds,
                                     progress=False, route=metric)
                    except GenerationError as exc:
                        r = exc.result
                    row = {"geometry": geo_name, "map": map_name, "band": list(band), "asked": args.count,
                           "found": r.found, "filled": r.found >= args.count, "values": [round(v, 4) for v in
                                                                                         r.difficulties],
                           "episodes": r.episodes, "search_steps": r.search_steps, "rated": rater.rated,
                           "unbuildable": rater.unbuildable, "rating_cpu_s": round(timed.cpu_s, 2),
                           "s_per_rating": round(timed.cpu_s / rater.rated, 3) if rater.rated else None,
                           "rated_range": [round(min(timed.values), 4), round(max(timed.values), 4)] if timed.values else None,
                           "wall_s": round(r.seconds, 1), "cpu_s": round(r.cpu_seconds, 1), "key": rater.key}
                    rows.append(row)
                    if row["filled"]:
                        filled.append(b)
                    print(f"{geo_name:8s} {map_name:18s} {band[0]:.1f}-{band[1]:.1f}: found {r.found}/{args.count} "
                          f"rated {rater.rated} ({row['s_per_rating']} CPU-s each) unbuildable {rater.unbuildable} "
                          f"{r.seconds:.1f} s", flush=True)
                seen = [v for row in rows[-N_BANDS:] if row["rated_range"] for v in row["rated_range"]]
                summary.append({"geometry": geo_name, "geometry_values": geometry(world), "map": map_name,
                                "rated_range": [min(seen), max(seen)] if seen else None,
                                "bands_filled": len(filled), "bands": [f"{b / N_BANDS:.1f}-{(b + 1) / N_BANDS:.1f}"
                                                                       for b in filled]})
    rated = sum(r["rated"] for r in rows)
    per = sum(r["rating_cpu_s"] for r in rows) / rated if rated else None
    out = {"provenance": provenance(), "count": args.count, "seconds_per_band": args.seconds, "seed": args.seed,
           "bands": N_BANDS, "model": f"{args.park_model} ({args.model.key})", "summary": summary,
           "seconds_per_rating": round(per, 3) if per else None, "garages_rated": rated,
           "wall_s": round(time.perf_counter() - t_all, 1), "rows": rows}
    args.json.parent.mkdir(parents=True, exist_ok=True)
    write_json(args.json, out, indent=1)
    for s in summary:
        print(f"{s['geometry']:8s} {s['map']:18s} {s['bands_filled']} of {N_BANDS} bands: {', '.join(s['bands'])} "
              f"(garages rated {s['rated_range']})")
    print(f"{rated} garages rated, {per:.3f} CPU-s per rating; {out['wall_s']:.0f} s in all -> {args.json}")


def searched(args: argparse.Namespace, names: list[str]) -> None:
    """``--search``: one generate_in_geometries call per map and band over the named geometries."""
    t_all = time.perf_counter()
    rows, summary = [], []
    with tempfile.TemporaryDirectory() as tmp:
        for map_name in args.maps:
            filled = []
            for b in range(N_BANDS):
                band = (b / N_BANDS, (b + 1) / N_BANDS)
                raters = {n: ParkRater(world_with(PARK_GEOMETRIES[n].world), model=args.model, seed=args.seed)
                          for n in names}
                t0 = time.perf_counter()
                try:
                    tried = generate_in_geometries(map_name, band, args.count, Path(tmp) / f"{map_name}_{b}.sqlite",
                                                   raters, max_seconds=args.seconds, seed=args.seed, progress=False)
                except GenerationError as exc:
                    tried = exc.tried
                found = {t.name: t.result.found for t in tried if t.result is not None and t.result.found}
                row = {"map": map_name, "band": list(band), "asked": args.count, "found": sum(found.values()),
                       "filled": sum(found.values()) >= args.count, "found_in": found,
                       "order": [t.name for t in tried], "probe_medians": {t.name: round(t.probe, 4) for t in tried},
                       "values": {t.name: [round(v, 4) for v in t.result.difficulties] for t in tried if t.result},
                       "rated": sum(t.rater.rated for t in tried),
                       "wall_s": round(time.perf_counter() - t0, 1)}
                rows.append(row)
                if row["filled"]:
                    filled.append(f"{band[0]:.1f}-{band[1]:.1f}")
                print(f"{map_name:18s} {band[0]:.1f}-{band[1]:.1f}: found {row['found']}/{args.count} in {found} "
                      f"(order {row['order']}) {row['wall_s']:.1f} s", flush=True)
            summary.append({"map": map_name, "bands_filled": len(filled), "bands": filled})
    out = {"provenance": provenance(), "count": args.count, "seconds_per_band": args.seconds, "seed": args.seed,
           "bands": N_BANDS, "model": f"{args.park_model} ({args.model.key})", "geometries": names, "summary": summary,
           "wall_s": round(time.perf_counter() - t_all, 1), "rows": rows}
    args.json.parent.mkdir(parents=True, exist_ok=True)
    write_json(args.json, out, indent=1)
    for s in summary:
        print(f"{s['map']:18s} {s['bands_filled']} of {N_BANDS} bands: {', '.join(s['bands'])}")
    print(f"{out['wall_s']:.0f} s in all -> {args.json}")


if __name__ == "__main__":
    main()
