"""Benchmark: DQN training throughput (timesteps/s) and the env's share of training time.

    .venv/bin/python eval/bench_train.py [--maps tiny_7x11 m5_13x13_aligned] [--timesteps 20000]
                                         [--learners fast paper] [--seed 0] [--profile] [--set KEY=VALUE ...]

Each map gets one fresh run per learner (garage_mj.generation.training.LEARNERS: ``fast``, ``paper``)
in a temporary folder, the learners one after the other in the same minute. The env share is
the wall time spent inside env.step/reset (GarageGenEnv with its Monitor and FinalGarage
wrappers, timed by training.StepTimer) over the whole ``learn`` call. ``--profile`` also prints
the top functions by cumulative time under cProfile (which slows everything down a little) and the
share of the time in SB3's gradient updates (``DQN.train``), action choice (``predict``) and the
env. ``--set`` overrides DQNConfig fields of every learner (``--learners paper --set n_envs=8 net_arch=[64,64]
batch_size=128 train_freq=1 gradient_steps=1`` is generation/dqn_fast.toml).
"""

from __future__ import annotations

import argparse
import cProfile
import io
import pstats
import tempfile

try:
    import tomllib
except ImportError:  # Python 3.10
    import tomli as tomllib
from pathlib import Path

from garage_mj.generation.training import LEARNERS, load_dqn_config, train

SHARES = {  # cProfile functions whose cumulative time is reported as a share of learn()
    "gradient updates": ("dqn.py", "train"),
    "action choice": ("dqn.py", "predict"),
    "env step (all wrappers)": ("dummy_vec_env.py", "step_wait"),
    "env step (vector env)": ("vec_env.py", "step_wait"),
    "replay buffer add": ("buffers.py", "add"),
    "callbacks": ("callbacks.py", "on_step"),
}


def _overrides(items: list[str]) -> dict:
    """``KEY=VALUE`` pairs, VALUE in TOML syntax (``n_envs=8``, ``net_arch=[64, 64]``)."""
    return tomllib.loads("\n".join(items)) if items else {}


def _shares(prof: cProfile.Profile) -> dict[str, float]:
    stats = pstats.Stats(prof).stats  # (file, line, name) -> (cc, nc, tt, ct, callers)
    learn = max(ct for (f, _, n), (_, _, _, ct, _) in stats.items() if n == "learn")
    out = {}
    for label, (file, name) in SHARES.items():
        ct = sum(v[3] for (f, _, n), v in stats.items() if f.endswith(file) and n == name)
        out[label] = ct / learn
    return out


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--maps", nargs="+", default=["tiny_7x11", "m5_13x13_aligned"])
    ap.add_argument("--timesteps", type=int, default=20_000)
    ap.add_argument("--learners", nargs="+", choices=sorted(LEARNERS), default=["fast", "paper"],
                    help="learners to run, in this order (default: fast paper)")
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--profile", action="store_true", help="print the cProfile top 15 by cumulative time")
    ap.add_argument("--set", nargs="+", default=[], metavar="KEY=VALUE", help="DQNConfig overrides (TOML values)")
    args = ap.parse_args()
    print(f"DQN, {args.timesteps} timesteps per map and learner, seed {args.seed}"
          + (f", with {' '.join(args.set)}" if args.set else ""))
    print(f"{'map':<20} {'learner':<8} {'timesteps/s':>12} {'per CPU s':>10} {'env share':>10} {'episodes':>9} "
          f"{'garages':>8}")
    for m in args.maps:
        for learner in args.learners:
            # no checkpoint inside the timed part
            config = load_dqn_config(_overrides(args.set), learner=learner, checkpoint_every=10 * args.timesteps)
            with tempfile.TemporaryDirectory() as tmp:
                prof = cProfile.Profile() if args.profile else None
                if prof:
                    prof.enable()
                manifest = train(m, args.timesteps, args.seed, Path(tmp) / "run", config, progress=False)
                if prof:
                    prof.disable()
            s = manifest["last_session"]
            print(f"{m:<20} {learner:<8} {s['timesteps_per_s']:>12,.0f} {s['timesteps_per_cpu_s']:>10,.0f} "
                  f"{100 * s['env_share']:>9.1f}% {manifest['episodes']:>9} {manifest['garages_stored']:>8}", flush=True)
            if prof:
                buf = io.StringIO()
                pstats.Stats(prof, stream=buf).sort_stats("cumulative").print_stats(15)
                print(buf.getvalue())
                print("share of learn() under cProfile: " + ", ".join(
                    f"{k} {100 * v:.1f}%" for k, v in _shares(prof).items()))


if __name__ == "__main__":
    main()
