"""Benchmark: DQN training throughput (timesteps/s) and the env's share of training time.

    .venv/bin/python eval/bench_train.py [--maps tiny_7x11 m5_13x13_aligned] [--timesteps 20000]
                                         [--seed 0] [--profile]

Each map gets one fresh run with the default DQNConfig in a temporary folder. The env share is
the wall time spent inside env.step/reset (GarageGenEnv with its Monitor and FinalGarage
wrappers, timed by training.StepTimer) over the whole ``learn`` call. ``--profile`` also prints
the top functions by cumulative time under cProfile (which slows everything down a little).
"""

from __future__ import annotations

import argparse
import cProfile
import io
import pstats
import tempfile
from pathlib import Path

from garage_mj.training import DQNConfig, train


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--maps", nargs="+", default=["tiny_7x11", "m5_13x13_aligned"])
    ap.add_argument("--timesteps", type=int, default=20_000)
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--profile", action="store_true", help="print the cProfile top 15 by cumulative time")
    args = ap.parse_args()
    config = DQNConfig(checkpoint_every=10 * args.timesteps)  # no checkpoint inside the timed part
    print(f"DQN, default config, {args.timesteps} timesteps per map, seed {args.seed}, "
          f"learning starts after {config.learning_starts}")
    print(f"{'map':<20} {'timesteps/s':>12} {'env share':>10} {'episodes':>9} {'garages':>8}")
    for m in args.maps:
        with tempfile.TemporaryDirectory() as tmp:
            prof = cProfile.Profile() if args.profile else None
            if prof:
                prof.enable()
            manifest = train(m, args.timesteps, args.seed, Path(tmp) / "run", config, progress=False)
            if prof:
                prof.disable()
        s = manifest["last_session"]
        print(f"{m:<20} {s['timesteps_per_s']:>12,.0f} {100 * s['env_share']:>9.1f}% "
              f"{manifest['episodes']:>9} {manifest['garages_stored']:>8}")
        if prof:
            buf = io.StringIO()
            pstats.Stats(prof, stream=buf).sort_stats("cumulative").print_stats(15)
            print(buf.getvalue())


if __name__ == "__main__":
    main()
