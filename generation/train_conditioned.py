"""Train the difficulty-conditioned generators that ``garage-mj generate`` uses.

    # one map (a shipped name or your own map file), with the fast learner (the default: vector env, codes
    # window, LeanDQN); resumed when --out holds a run
    .venv/bin/python generation/train_conditioned.py --map m5_13x13_aligned --timesteps 200000 --out runs/gen_m5
    # the paper's DQN settings instead: --learner paper, or learner = "paper" in the config's [dqn] table
    # (its other keys override the learner's)
    .venv/bin/python generation/train_conditioned.py --map m5_13x13_aligned --timesteps 60000 --out runs/gen_m5_paper --learner paper
    # every map of the config, one after the other, copied to models/generators/<map>.zip + .json
    .venv/bin/python generation/train_conditioned.py --all generation/conditioned.toml --ship

Run folders go to runs/generators/<map> with --all (resumed when they exist). Logic lives in
garage_mj.generation.conditioned.train_conditioned; this script only loops and copies.
"""

from __future__ import annotations

import argparse
import json
import shutil
import time
from pathlib import Path

from garage_mj.generation.conditioned import (
    GENERATOR,
    GENERATOR_META,
    RUN_MANIFEST,
    load_generator_config,
    train_conditioned,
)
from garage_mj.generation.training import LEARNERS

ROOT = Path(__file__).resolve().parent.parent
SHIP_DIR = ROOT / "models" / "generators"


def _train(map: str, timesteps: int, seed: int, out: Path, config: Path | None, progress: bool,
           learner: str | None = None) -> dict:
    dqn, cond, _ = load_generator_config(config, learner=learner)
    resume = (out / RUN_MANIFEST).exists()
    t0 = time.perf_counter()
    meta = train_conditioned(map, timesteps, seed, out, dqn=dqn, condition=cond, resume=resume, progress=progress)
    last = meta["curve"][-1] if meta["curve"] else {}
    print(f"{meta['map']}: {meta['timesteps']} timesteps, {meta['episodes']} episodes in "
          f"{time.perf_counter() - t0:.0f} s this session ({meta['train_wall_s']:.0f} s in all); last chunk: "
          f"usable {last.get('usable')}, in band {last.get('in_band')} -> {out / GENERATOR}", flush=True)
    return meta


def _ship(out: Path, name: str) -> None:
    SHIP_DIR.mkdir(parents=True, exist_ok=True)
    shutil.copyfile(out / GENERATOR, SHIP_DIR / f"{name}.zip")
    shutil.copyfile(out / GENERATOR_META, SHIP_DIR / f"{name}.json")
    print(f"shipped {SHIP_DIR / (name + '.zip')} ({(SHIP_DIR / (name + '.zip')).stat().st_size // 1024} KB)")


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--map", help="shipped map name or map file")
    ap.add_argument("--timesteps", type=int, default=50_000)
    ap.add_argument("--out", type=Path, help="run folder (an existing run is resumed)")
    ap.add_argument("--config", type=Path, help="TOML with [dqn] and [condition] tables")
    ap.add_argument("--learner", choices=sorted(LEARNERS),
                    help="DQN settings to start from (default: the config's [dqn] learner, else fast)")
    ap.add_argument("--all", type=Path, metavar="CONFIG", help="train every map of CONFIG's [timesteps] table")
    ap.add_argument("--maps", nargs="+", help="with --all: only these maps")
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--ship", action="store_true", help="copy the generator to models/generators/<map>.zip")
    ap.add_argument("--no-progress", action="store_true")
    args = ap.parse_args()
    if args.all:
        _, _, steps = load_generator_config(args.all)
        for name, n in steps.items():
            if args.maps and name not in args.maps:
                continue
            out = ROOT / "runs" / "generators" / name
            _train(name, n, args.seed, out, args.all, not args.no_progress, args.learner)
            if args.ship:
                _ship(out, name)
        return
    if not args.map or not args.out:
        ap.error("pass --map and --out, or --all CONFIG")
    meta = _train(args.map, args.timesteps, args.seed, args.out, args.config, not args.no_progress, args.learner)
    if args.ship:
        _ship(args.out, meta["map"])
    print(json.dumps(meta["curve"][-1] if meta["curve"] else {}))


if __name__ == "__main__":
    main()
