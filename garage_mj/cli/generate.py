"""``garage-mj generate``: N garages of a map in a difficulty (and coverage) band, from a trained generator."""

from __future__ import annotations

import argparse
from pathlib import Path

from garage_mj.cli import UserError
from garage_mj.cli._common import positive_int, seed, unit_range, user_errors


def register(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser(
        "generate",
        help="store N garages of a map in a difficulty band, from a trained conditioned generator",
        description=(
            "Roll out the map's difficulty-conditioned DQN generator (shipped in models/generators/ for "
            "every shipped map, or --model) with the band in its observation, epsilon-greedy with a "
            "seeded epsilon per episode so that distinct garages appear, and store every distinct "
            "usable garage whose difficulty (and coverage) lies in the band in the library, until "
            "--count are found. The same --seed gives the same garages. If --max-episodes episodes "
            "do not find --count, the ones found are kept and the command says how many (exit status 2). "
            "For your own map file, train a generator first with generation/train_conditioned.py "
            "(about 20-30 s per 10,000 timesteps on one core; 80,000 for a 13x13 map) and pass --model, "
            "or pass a shipped generator (--model m4_13x13_offset): generators see only a window "
            "around the car, so they run on any map."
        ),
        epilog="example: garage-mj generate --map m5_13x13_aligned --difficulty 0.3 0.4 --count 20 "
               "--library garages.sqlite",
    )
    p.add_argument("--map", required=True, help="shipped map name (garage-mj maps list) or map file")
    p.add_argument("--difficulty", required=True, nargs=2, type=unit_range, metavar=("LO", "HI"),
                   help="difficulty band [LO, HI] (0-1)")
    p.add_argument("--coverage", nargs=2, type=unit_range, metavar=("LO", "HI"), help="coverage band [LO, HI] (0-1)")
    p.add_argument("--count", required=True, type=positive_int, help="distinct garages to find")
    p.add_argument("--library", required=True, type=Path, help="library file (created if missing)")
    p.add_argument("--model", help="generator file, or a shipped map's name to use its generator "
                   "(default: the shipped generator of --map)")
    p.add_argument("--seed", type=seed, default=0, help="random seed (default 0)")
    p.add_argument("--max-episodes", type=positive_int, metavar="E",
                   help="episode budget (default 2,000 + 200 x COUNT)")
    p.add_argument("--max-seconds", type=float, metavar="S", help="stop after S seconds of rollouts (wall clock)")
    p.add_argument("--no-progress", action="store_true", help="no progress bar")
    p.set_defaults(func=run)


@user_errors
def run(args: argparse.Namespace) -> int:
    from garage_mj.generator import generate

    for name in ("difficulty", "coverage"):
        band = getattr(args, name)
        if band is not None and band[0] > band[1]:
            raise UserError(f"--{name} {band[0]} {band[1]}: LO is above HI")
    r = generate(args.map, tuple(args.difficulty), args.count, args.library,
                 coverage=tuple(args.coverage) if args.coverage else None, model=args.model, seed=args.seed,
                 max_episodes=args.max_episodes, max_seconds=args.max_seconds, progress=not args.no_progress)
    lo, hi = min(r.difficulties), max(r.difficulties)
    print(f"{r.found} distinct garages with difficulty {lo:.3f}-{hi:.3f} in {r.episodes} episodes "
          f"({r.seconds:.1f} s); {r.stored} new in {args.library}")
    return 0
