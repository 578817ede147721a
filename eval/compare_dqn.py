"""Learning-quality check of DQN learners: seeds x maps x timesteps, resumable, one run at a time.

    .venv/bin/python eval/compare_dqn.py [--configs paper fast] [--maps m5_13x13_aligned m7_13x13_u] \\
        [--seeds 0 1 2] [--timesteps 200000] [--out runs/compare_learners] [--csv docs/compare_learners.csv]
    .venv/bin/python eval/compare_dqn.py --summary-only      # the table from what has finished

``paper`` and ``fast`` are the learners of ``garage_mj.generation.training.LEARNERS``; ``baseline`` is the
DQNConfig that was the default before the throughput work (written out here, so it does not move when
the default changes); ``dqn_fast`` is ``generation/dqn_fast.toml`` (8 envs, (64, 64), one step of 128 per
8 timesteps); the ``fast_*`` names are the fast learner with one or more settings changed
(``FAST_VARIANTS``: its earlier settings and the alternatives measured against it). Each run is a normal
training run folder ``OUT/<config>/<map>_s<seed>``; a finished one is skipped, an interrupted one
resumes from its newest checkpoint. Per run: mean return of the last 100 episodes (``monitor.csv``),
distinct usable garages stored in the run's library, and timesteps/s. The training return mixes in each
learner's own exploration (the fast learner ends at epsilon 0.1, the paper learner at 0.05), so each final
model is also run for 100 episodes at one epsilon for all, 0.05, with a fixed seed: the mean return and
the share of usable garages of the learned policy (cached in the run folder as ``policy_eval.json``). The summary (per config and map:
mean and 95% t-interval over seeds) goes to ``docs/compare_learners.csv`` and is printed.
"""

from __future__ import annotations

import argparse
import csv
import dataclasses
import json
import math
import sqlite3
from pathlib import Path

import numpy as np

from garage_mj.generation.training import (
    LEARNERS,
    DQNConfig,
    load_dqn_config,
    make_vec_env,
    read_manifest,
    train,
)

# the default DQNConfig before the throughput work (commit 1efa9fa), the reference configuration
BASELINE = dict(
    learning_rate=5e-4, buffer_size=50_000, learning_starts=1_000, batch_size=64, tau=1.0, gamma=0.99,
    train_freq=4, gradient_steps=1, n_steps=1, target_update_interval=1_000, exploration_fraction=0.2,
    exploration_initial_eps=1.0, exploration_final_eps=0.05, max_grad_norm=10.0, net_arch=(256, 256),
    torch_threads=1, view_size=7, max_errors=10,
)
FAST_TOML = Path(__file__).resolve().parent.parent / "generation" / "dqn_fast.toml"
# the fast learner's earlier settings and the alternatives weighed against it, as overrides of
# LEARNERS["fast"] with FAST_BEFORE on top (the settings it had while they were measured, so each name keeps
# meaning the runs it made); each suffix names one: t1k the target network renewed every 1,000 timesteps (31
# gradient steps) instead of 8,000 (t2k, t4k, t16k, t32k likewise), eps05 exploration down to 0.05 instead
# of 0.1, lr5e4 learning rate 5e-4 instead of 1e-3, n1 1-step instead of 3-step returns, g2 two gradient
# steps of 128 per 32 timesteps, 64envs 64 envs and batches of 512, f2 / f4 one gradient step of 512 /
# 1,024 per 64 / 128 timesteps (the same replay ratio in half / a quarter of the steps), ls10k learning
# from 10,000 timesteps on instead of 1,000. fast_t1k_eps05 is the fast learner as first defined.
FAST_BEFORE = {"target_update_interval": 8_000, "learning_starts": 1_000}
FAST_VARIANTS = {
    "fast_t1k_eps05": {"target_update_interval": 1_000, "exploration_final_eps": 0.05},
    "fast_t1k": {"target_update_interval": 1_000},
    "fast_t1k_lr5e4": {"target_update_interval": 1_000, "learning_rate": 5e-4},
    "fast_t1k_n1": {"target_update_interval": 1_000, "n_steps": 1},
    "fast_t1k_64envs": {"target_update_interval": 1_000, "n_envs": 64, "batch_size": 512},
    "fast_t1k_eps05_64envs": {"target_update_interval": 1_000, "exploration_final_eps": 0.05, "n_envs": 64,
                              "batch_size": 512},
    "fast_t1k_eps05_g2": {"target_update_interval": 1_000, "exploration_final_eps": 0.05, "batch_size": 128,
                          "gradient_steps": 2},
    "fast_eps05": {"exploration_final_eps": 0.05},
    "fast_n1": {"n_steps": 1},
    "fast_f2": {"train_freq": 2, "batch_size": 512},
    "fast_f2_t16k": {"train_freq": 2, "batch_size": 512, "target_update_interval": 16_000},
    "fast_t16k": {"target_update_interval": 16_000},
    "fast_f4": {"train_freq": 4, "batch_size": 1024},
    "fast_f4_t32k": {"train_freq": 4, "batch_size": 1024, "target_update_interval": 32_000},
    "fast_ls10k": {"learning_starts": 10_000},
    "fast_t1k_ls10k": {"target_update_interval": 1_000, "learning_starts": 10_000},
    "fast_t2k_ls10k": {"target_update_interval": 2_000, "learning_starts": 10_000},
    "fast_t4k_ls10k": {"target_update_interval": 4_000, "learning_starts": 10_000},
}
LAST_EPISODES = 100  # episodes averaged for the final return
EVAL_EPISODES, EVAL_EPSILON, EVAL_SEED = 100, 0.05, 12345  # the final policy's evaluation, the same for all
# two-sided 95% Student t quantiles by degrees of freedom
T95 = {1: 12.706, 2: 4.303, 3: 3.182, 4: 2.776, 5: 2.571, 6: 2.447, 7: 2.365, 8: 2.306, 9: 2.262, 10: 2.228}


def config_named(name: str, checkpoint_every: int) -> DQNConfig:
    if name in LEARNERS:
        return load_dqn_config(learner=name, checkpoint_every=checkpoint_every)
    if name == "baseline":
        return DQNConfig(**BASELINE, checkpoint_every=checkpoint_every)
    # earlier settings of the fast learner and the candidates weighed against them (docs/generate.md)
    if name in FAST_VARIANTS:
        return load_dqn_config({**FAST_BEFORE, **FAST_VARIANTS[name]}, learner="fast", checkpoint_every=checkpoint_every)
    if name == "dqn_fast":
        return load_dqn_config(FAST_TOML, learner="paper", checkpoint_every=checkpoint_every)
    raise SystemExit(f"unknown config {name!r}: use {', '.join([*LEARNERS, *FAST_VARIANTS])}, baseline or dqn_fast")


def difficulty_range(run: Path) -> tuple[float, float] | None:
    """Lowest and highest difficulty of the garages the run's own library holds."""
    path = run / "library.sqlite"
    if not path.exists():
        return None
    con = sqlite3.connect(f"file:{path}?mode=ro", uri=True)
    try:
        lo, hi = con.execute("SELECT MIN(difficulty), MAX(difficulty) FROM garages").fetchone()
    finally:
        con.close()
    return None if lo is None else (float(lo), float(hi))


def policy_eval(run: Path) -> dict:
    """The run's final model over ``EVAL_EPISODES`` episodes at epsilon ``EVAL_EPSILON``: mean return and usable share.

    Every learner is run the same way (its own observation and env batching, the same epsilon and seed),
    so the figures compare the learned policies, not the exploration each trained with. Cached in
    ``run/policy_eval.json``.
    """
    cache = run / "policy_eval.json"
    key = {"episodes": EVAL_EPISODES, "epsilon": EVAL_EPSILON, "seed": EVAL_SEED}
    if cache.exists():
        got = json.loads(cache.read_text())
        if all(got.get(k) == v for k, v in key.items()):
            return got
    from stable_baselines3.common.evaluation import evaluate_policy

    from garage_mj.generation.runs import load_dqn

    manifest = read_manifest(run)
    config = load_dqn_config(manifest["config"])
    venv, _ = make_vec_env(manifest.get("map_source", manifest["map"]), config, None)
    venv.seed(EVAL_SEED)
    model = load_dqn(run / "final_model.zip", config, env=venv)
    model.set_random_seed(EVAL_SEED)
    model.exploration_rate = EVAL_EPSILON
    usable: list[bool] = []

    def count(local: dict, _globals: dict) -> None:
        i, info = local["i"], local["info"]
        if local["done"] and "episode" in info and local["episode_counts"][i] < local["episode_count_targets"][i]:
            usable.append(bool(info.get("usable")))

    returns, _ = evaluate_policy(model, venv, n_eval_episodes=EVAL_EPISODES, deterministic=False,
                                 return_episode_rewards=True, callback=count)
    venv.close()
    out = {**key, "return_mean": float(np.mean(returns)), "usable_share": float(np.mean(usable))}
    cache.write_text(json.dumps(out, indent=1) + "\n")
    return out


def run_result(run: Path) -> dict | None:
    """Metrics of a finished run folder, or None."""
    try:
        manifest = read_manifest(run)
    except Exception:
        return None
    if manifest.get("status") != "finished":
        return None
    returns = np.loadtxt(run / "monitor.csv", delimiter=",", skiprows=2, ndmin=2)[:, 0]
    session = manifest.get("last_session", {})
    return {
        "timesteps": manifest["timesteps"], "episodes": manifest["episodes"],
        "return_last100": float(returns[-LAST_EPISODES:].mean()),
        "garages_stored": manifest["garages_stored"],
        "policy": policy_eval(run),
        "difficulty_range": difficulty_range(run),
        "timesteps_per_s": session.get("timesteps_per_s"),
        "timesteps_per_cpu_s": session.get("timesteps_per_cpu_s"),
        "config": manifest["config"],
    }


def interval(values: list[float]) -> tuple[float, float]:
    """Mean and the half-width of its 95% t-interval (nan for fewer than 2 values)."""
    a = np.asarray(values, dtype=float)
    if len(a) < 2:
        return float(a.mean()) if len(a) else math.nan, math.nan
    return float(a.mean()), T95.get(len(a) - 1, 1.96) * float(a.std(ddof=1)) / math.sqrt(len(a))


def summarise(out: Path, csv_path: Path) -> None:
    rows = []
    for cfg_dir in sorted(p for p in out.iterdir() if p.is_dir()):
        by_map: dict[tuple[str, int], list[tuple[int, dict]]] = {}
        try:
            want = dataclasses.asdict(config_named(cfg_dir.name, checkpoint_every=1))
        except SystemExit:
            want = None
        for run in sorted(cfg_dir.iterdir()):
            res = run_result(run)
            if res is None:
                continue
            # keys a run predates (n_envs, fused Adam...) had their defaults then
            got = {**{k: (list(v) if isinstance(v, tuple) else v) for k, v in dataclasses.asdict(DQNConfig()).items()},
                   **res["config"]}
            if want is not None and any(got.get(k) != (list(v) if isinstance(v, tuple) else v)
                                        for k, v in want.items() if k != "checkpoint_every"):
                print(f"skipping {run}: trained under another config than {cfg_dir.name!r}")
                continue
            map_name, seed = run.name.rsplit("_s", 1)
            by_map.setdefault((map_name, res["timesteps"]), []).append((int(seed), res))
        for (map_name, steps), unsorted in sorted(by_map.items()):
            runs = sorted(unsorted, key=lambda x: x[0])  # by seed
            ret = interval([r["return_last100"] for _, r in runs])
            gar = interval([r["garages_stored"] for _, r in runs])
            pol = interval([r["policy"]["return_mean"] for _, r in runs])
            use = interval([r["policy"]["usable_share"] for _, r in runs])
            tps = interval([r["timesteps_per_s"] for _, r in runs if r["timesteps_per_s"]])
            cps = interval([r["timesteps_per_cpu_s"] for _, r in runs if r.get("timesteps_per_cpu_s")])
            ranges = [r["difficulty_range"] for _, r in runs if r.get("difficulty_range")]
            rows.append({
                "config": cfg_dir.name, "map": map_name, "timesteps": steps,
                "seeds": " ".join(str(s) for s, _ in runs),
                "return_last100_mean": round(ret[0], 2), "return_last100_ci95": round(ret[1], 2),
                "garages_mean": round(gar[0], 1), "garages_ci95": round(gar[1], 1),
                "policy_return_mean": round(pol[0], 2), "policy_return_ci95": round(pol[1], 2),
                "policy_usable_mean": round(use[0], 3), "policy_usable_ci95": round(use[1], 3),
                "timesteps_per_s_mean": round(tps[0], 0),
                "timesteps_per_cpu_s_mean": round(cps[0], 0) if not math.isnan(cps[0]) else "",
                "difficulty_lo_mean": round(float(np.mean([a for a, _ in ranges])), 3) if ranges else "",
                "difficulty_hi_mean": round(float(np.mean([b for _, b in ranges])), 3) if ranges else "",
                "per_seed_difficulty_range": " ".join(f"{a:.2f}-{b:.2f}" for a, b in ranges),
                "per_seed_return": " ".join(f"{r['return_last100']:.1f}" for _, r in runs),
                "per_seed_garages": " ".join(str(r["garages_stored"]) for _, r in runs),
                "per_seed_policy_return": " ".join(f"{r['policy']['return_mean']:.1f}"
                                                   for _, r in runs),
                "config_json": json.dumps(runs[0][1]["config"], sort_keys=True),
            })
    if not rows:
        print("no finished runs yet")
        return
    csv_path.parent.mkdir(parents=True, exist_ok=True)
    with open(csv_path, "w", newline="") as f:
        w = csv.DictWriter(f, fieldnames=list(rows[0]))
        w.writeheader()
        w.writerows(rows)
    print(f"{'config':<10} {'map':<18} {'steps':>7} {'seeds':>6} {'return last 100':>20} "
          f"{'policy return':>17} {'garages':>16} {'ts/s':>6}")
    for r in rows:
        print(f"{r['config']:<10} {r['map']:<18} {r['timesteps']:>7} {r['seeds']:>6} "
              f"{r['return_last100_mean']:>11.1f} +- {r['return_last100_ci95']:>5.1f} "
              f"{r['policy_return_mean']:>8.1f} +- {r['policy_return_ci95']:>5.1f} "
              f"{r['garages_mean']:>8.1f} +- {r['garages_ci95']:>5.1f} {r['timesteps_per_s_mean']:>6.0f}")
    print(f"wrote {csv_path}")


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--configs", nargs="+", default=["paper", "fast"])
    ap.add_argument("--maps", nargs="+", default=["m5_13x13_aligned", "m7_13x13_u"])
    ap.add_argument("--seeds", nargs="+", type=int, default=[0, 1, 2])
    ap.add_argument("--timesteps", type=int, default=200_000)
    ap.add_argument("--out", type=Path, default=Path("runs/compare_learners"))
    ap.add_argument("--csv", type=Path, default=Path("docs/compare_learners.csv"))
    ap.add_argument("--summary-only", action="store_true")
    args = ap.parse_args()
    if not args.summary_only:
        # seed-major order: if the comparison is cut short, the seeds done are done for every config
        for seed in args.seeds:
            for name in args.configs:
                config = config_named(name, checkpoint_every=max(args.timesteps // 8, 1))
                for map_name in args.maps:
                    run = args.out / name / f"{map_name}_s{seed}"
                    if run_result(run) is not None:
                        continue
                    resume = (run / "run.json").exists()
                    m = train(map_name, args.timesteps, seed, run, None if resume else config,
                              resume=resume, progress=False)
                    s = m["last_session"]
                    print(f"{name} {map_name} seed {seed}: {s['timesteps_per_s']} timesteps/s, "
                          f"{m['garages_stored']} garages", flush=True)
                    summarise(args.out, args.csv)
    summarise(args.out, args.csv)


if __name__ == "__main__":
    main()
