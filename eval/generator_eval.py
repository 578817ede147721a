"""What a set of conditioned generators paints by itself: distinct in-band garages per 0.1-wide bin.

    .venv/bin/python eval/generator_eval.py [--generators models/generators] [--label shipped]
        [--maps m4_13x13_offset ...] [--episodes 300] [--seed 0] [--json docs/generator_eval.json]

For each map and each difficulty bin [b/10, (b+1)/10] that overlaps the range the generator was trained
on (its ``condition`` difficulty_lo..hi), ``garage_mj.generation.generator.generate`` runs the generator's
policy stage alone (``search=False``) for ``--episodes`` episodes, the same seeds for every set of
generators, and the row records the distinct usable garages that landed in the bin and the CPU seconds
it took. That is stage 1 of ``garage-mj generate`` with a fixed episode budget, so two sets of
generators (``--generators`` folders holding ``<map>.zip`` and ``<map>.json``, or run folders
``<map>/generator.zip``) compare on the same footing. ``--json`` adds the set under ``--label`` to
the file (other labels are kept), with its provenance.
"""

from __future__ import annotations

import argparse
import json
import tempfile
import time
from pathlib import Path

from _provenance import provenance  # eval/_provenance.py: command, date, machine, commit

from garage_mj.generation.generator import GenerationError, generate, generator_meta

MAPS = ["tiny_7x11", "m4_13x13_offset", "m5_13x13_aligned", "m6_13x13_s", "m7_13x13_u"]
N_BINS = 10


def generator_file(folder: Path, map_name: str) -> Path:
    """``folder/<map>.zip`` (a shipped layout) or ``folder/<map>/generator.zip`` (a run folder)."""
    for path in (folder / f"{map_name}.zip", folder / map_name / "generator.zip"):
        if path.is_file():
            return path
    raise SystemExit(f"--generators {folder}: no {map_name}.zip or {map_name}/generator.zip there")


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--generators", type=Path, default=Path("models/generators"),
                    help="folder of <map>.zip + <map>.json, or of run folders <map>/generator.zip")
    ap.add_argument("--label", default="shipped", help="name of this set of generators in the JSON")
    ap.add_argument("--maps", nargs="+", default=MAPS, help="shipped map names or map files")
    ap.add_argument("--episodes", type=int, default=300, help="policy episodes per bin")
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--json", type=Path, help="add the rows under --label to this file")
    args = ap.parse_args()
    prov = provenance()
    rows = []
    print(f"{args.label}: distinct in-band garages in {args.episodes} policy episodes per bin")
    for map_name in args.maps:  # a shipped map's name or a map file (its generator named by the file's stem)
        path = generator_file(args.generators, Path(map_name).stem)
        meta = generator_meta(path)
        if not meta:
            raise SystemExit(f"{path}: no {path.stem}.json or generator.json beside it (the generator's settings)")
        lo, hi = meta["condition"]["difficulty_lo"], meta["condition"]["difficulty_hi"]
        line = []
        for b in range(N_BINS):
            band = (b / N_BINS, (b + 1) / N_BINS)
            if band[1] <= lo or band[0] >= hi:
                continue
            t0 = time.process_time()
            with tempfile.TemporaryDirectory() as tmp:
                try:  # asking for more than the episodes can give: the policy stage runs all of them
                    result = generate(map_name, band, 10**6, Path(tmp) / "l.sqlite", model=path, seed=args.seed,
                                      max_episodes=args.episodes, search=False, progress=False)
                except GenerationError as exc:
                    result = exc.result
            assert result is not None
            rows.append({"map": map_name, "bin": f"{band[0]:.1f}-{band[1]:.1f}", "episodes": result.episodes,
                         "found": result.found, "cpu_s": round(time.process_time() - t0, 2),
                         "generator_timesteps": meta.get("timesteps"),
                         "vector_env": bool(meta.get("dqn", {}).get("vector_env", False))})
            line.append(f"{band[0]:.1f}:{result.found}")
        found = sum(r["found"] for r in rows if r["map"] == map_name)
        print(f"  {map_name:<18} {found:>5} in all   " + "  ".join(line), flush=True)
    if args.json:
        data = json.loads(args.json.read_text()) if args.json.is_file() else {}
        data[args.label] = {"provenance": prov, "generators": str(args.generators), "episodes_per_bin": args.episodes,
                            "seed": args.seed, "rows": rows}
        args.json.write_text(json.dumps(data, indent=1) + "\n")


if __name__ == "__main__":
    main()
