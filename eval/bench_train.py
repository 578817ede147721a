"""Benchmark: DQN training throughput (timesteps/s) and the env's share of training time.

    .venv/bin/python eval/bench_train.py [--maps tiny_7x11 m5_13x13_aligned] [--timesteps 20000]
                                         [--learners fast paper] [--seed 0] [--profile] [--set KEY=VALUE ...]

Each map gets one fresh run per learner (garage_mj.generation.training.LEARNERS: ``fast``, ``paper``)
in a temporary folder, the learners one after the other in the same minute. ``timesteps/s`` is the
whole run's rate; ``learning`` the rate from ``learning_starts`` on, once every vector step also trains
(a learner that starts learning later is not credited with its cheaper first timesteps). The env share is
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
import json
import pstats
import tempfile
import time

try:
    import tomllib
except ImportError:  # Python 3.10
    import tomli as tomllib
from pathlib import Path

import numpy as np
from _provenance import provenance  # eval/_provenance.py: command, date, machine, commit
from stable_baselines3.common.callbacks import BaseCallback

from garage_mj.generation.training import LEARNERS, load_dqn_config, train


class LearningClock(BaseCallback):
    """When the run's gradient updates start (``learning_starts``) and end: the rate while learning."""

    def __init__(self, learning_starts: int) -> None:
        super().__init__()
        self.learning_starts, self.start, self.steps0 = learning_starts, None, 0

    def _on_step(self) -> bool:
        if self.start is None and self.num_timesteps >= self.learning_starts:
            self.start, self.steps0 = time.perf_counter(), self.num_timesteps
        return True

    def rate(self) -> float | None:
        if self.start is None or self.num_timesteps <= self.steps0:
            return None
        return (self.num_timesteps - self.steps0) / (time.perf_counter() - self.start)

# per-round figure -> (its median's key per learner, the fast/paper ratio's key) in the JSON summary
SUMMARY_NAMES = {"timesteps_per_s": ("median", "fast_over_paper"),
                 "timesteps_per_s_learning": ("median_learning", "fast_over_paper_learning")}
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
    ap.add_argument("--rounds", type=int, default=1,
                    help="repeat the whole set of runs (the learners interleaved in each round, so a change in "
                         "the machine's load hits both)")
    ap.add_argument("--json", type=Path, help="also write every run's figures here, with their provenance")
    args = ap.parse_args()
    prov = provenance()  # before the runs: the load they start at
    rows = []
    print(f"DQN, {args.timesteps} timesteps per map and learner, seed {args.seed}"
          + (f", with {' '.join(args.set)}" if args.set else ""))
    print(f"{'map':<20} {'learner':<8} {'timesteps/s':>12} {'learning':>9} {'per CPU s':>10} {'env share':>10} "
          f"{'episodes':>9} {'garages':>8}")
    for rnd, m, learner in ((r, m, lr) for r in range(args.rounds) for m in args.maps for lr in args.learners):
        # no checkpoint inside the timed part
        config = load_dqn_config(_overrides(args.set), learner=learner, checkpoint_every=10 * args.timesteps)
        with tempfile.TemporaryDirectory() as tmp:
            prof = cProfile.Profile() if args.profile else None
            if prof:
                prof.enable()
            clock = LearningClock(config.learning_starts)
            manifest = train(m, args.timesteps, args.seed, Path(tmp) / "run", config, progress=False,
                             callbacks=[clock])
            if prof:
                prof.disable()
        s = manifest["last_session"]
        learning = clock.rate()
        rows.append({"round": rnd, "map": m, "learner": learner, "timesteps": s["timesteps"],
                     "timesteps_per_s": s["timesteps_per_s"], "timesteps_per_cpu_s": s["timesteps_per_cpu_s"],
                     "learning_starts": config.learning_starts, "timesteps_per_s_learning": learning,
                     "env_share": s["env_share"], "episodes": manifest["episodes"],
                     "garages": manifest["garages_stored"], "config": manifest["config"]})
        print(f"{m:<20} {learner:<8} {s['timesteps_per_s']:>12,.0f} "
              f"{'-' if learning is None else f'{learning:,.0f}':>9} {s['timesteps_per_cpu_s']:>10,.0f} "
              f"{100 * s['env_share']:>9.1f}% {manifest['episodes']:>9} {manifest['garages_stored']:>8}", flush=True)
        if prof:
            buf = io.StringIO()
            pstats.Stats(prof, stream=buf).sort_stats("cumulative").print_stats(15)
            print(buf.getvalue())
            print("share of learn() under cProfile: " + ", ".join(
                f"{k} {100 * v:.1f}%" for k, v in _shares(prof).items()))

    if args.json:
        summary = {}
        for m in args.maps:
            summary[m] = {}
            for key, (median, ratio) in SUMMARY_NAMES.items():
                per = {lr: [r[key] for r in rows if r["map"] == m and r["learner"] == lr and r[key] is not None]
                       for lr in args.learners}
                for lr, v in per.items():
                    summary[m].setdefault(lr, {})[key] = v
                    summary[m][lr][median] = float(np.median(v)) if v else None
                if {"fast", "paper"} <= set(per) and per["fast"] and len(per["fast"]) == len(per["paper"]):
                    ratios = [f / p for f, p in zip(per["fast"], per["paper"])]
                    summary[m][ratio] = {"per_round": [round(x, 2) for x in ratios],
                                        "median": round(float(np.median(ratios)), 2)}
        args.json.parent.mkdir(parents=True, exist_ok=True)
        args.json.write_text(json.dumps({"timesteps": args.timesteps, "seed": args.seed, "summary": summary,
                                         "runs": rows, "provenance": prov}, indent=1) + "\n")
        print(f"wrote {args.json}")


if __name__ == "__main__":
    main()
