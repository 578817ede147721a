"""Benchmark: the fast learner's gradient step and action choice under SB3's DQN and under LeanDQN.

    .venv/bin/python eval/bench_lean_dqn.py [--rounds 5] [--steps 300] [--json docs/bench_lean_dqn.json]

Trains the fast learner for 12,000 timesteps on m5_13x13_aligned (so the replay buffer and the network
are those of a run), then times, on that one model and one thread, ``DQN.train`` against
``LeanDQN.train`` (one gradient step of 256 transitions: replay sample, target, loss, backward, clipping,
Adam) and ``DQN.predict`` against ``LeanDQN.predict`` (epsilon-greedy actions for 32 observations at the
run's final epsilon), interleaved for ``--rounds`` rounds; medians per round. Both compute the same
numbers (tests/test_vec_env.py); only the bookkeeping around them differs.
"""

from __future__ import annotations

import argparse
import json
import tempfile
import time
from pathlib import Path

import numpy as np
import torch
from _provenance import provenance  # eval/_provenance.py: command, date, machine, commit
from stable_baselines3 import DQN
from stable_baselines3.common.callbacks import BaseCallback

from garage_mj.generation.lean_dqn import LeanDQN
from garage_mj.generation.training import load_dqn_config, train


class _Keep(BaseCallback):
    def _on_step(self) -> bool:
        self.kept = self.model
        return True


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--rounds", type=int, default=5)
    ap.add_argument("--steps", type=int, default=300, help="gradient steps (and 4x as many action choices) per round")
    ap.add_argument("--json", type=Path)
    args = ap.parse_args()
    prov = provenance()
    config = load_dqn_config(learner="fast", checkpoint_every=10**9)
    keep = _Keep()
    with tempfile.TemporaryDirectory() as tmp:
        train("m5_13x13_aligned", 12_000, 0, Path(tmp) / "run", config, progress=False, callbacks=[keep])
    model = keep.kept
    assert isinstance(model, LeanDQN)
    torch.set_num_threads(1)
    obs = model._last_obs.copy()  # the 32 envs' current observations
    times: dict[str, list[float]] = {k: [] for k in ("dqn_train_ms", "lean_train_ms", "dqn_act_ms", "lean_act_ms")}
    # LeanDQN replaces the policy's set_training_mode with a no-op on this instance; DQN is timed with its own
    lean_mode = model.policy.__dict__["set_training_mode"]
    for _ in range(args.rounds):
        for name, algo in (("dqn", DQN), ("lean", LeanDQN)):
            if name == "dqn":
                del model.policy.set_training_mode
            else:
                model.policy.set_training_mode = lean_mode
            t = time.perf_counter()
            for _ in range(args.steps):
                algo.train(model, 1, config.batch_size)
            times[f"{name}_train_ms"].append((time.perf_counter() - t) / args.steps * 1e3)
            t = time.perf_counter()
            for _ in range(4 * args.steps):
                algo.predict(model, obs)
            times[f"{name}_act_ms"].append((time.perf_counter() - t) / (4 * args.steps) * 1e3)
    med = {k: round(float(np.median(v)), 3) for k, v in times.items()}
    summary = {**med, "train_speedup": round(med["dqn_train_ms"] / med["lean_train_ms"], 2),
               "act_speedup": round(med["dqn_act_ms"] / med["lean_act_ms"], 2)}
    print(f"gradient step (batch {config.batch_size}): DQN {med['dqn_train_ms']:.2f} ms, LeanDQN "
          f"{med['lean_train_ms']:.2f} ms ({summary['train_speedup']:.2f}x); action choice for 32 envs: DQN "
          f"{med['dqn_act_ms']:.3f} ms, LeanDQN {med['lean_act_ms']:.3f} ms ({summary['act_speedup']:.2f}x)")
    if args.json:
        args.json.parent.mkdir(parents=True, exist_ok=True)
        args.json.write_text(json.dumps({"rounds": args.rounds, "steps": args.steps, "batch": config.batch_size,
                                         "summary": summary, "per_round": times, "provenance": prov}, indent=1) + "\n")
        print(f"wrote {args.json}")


if __name__ == "__main__":
    main()
