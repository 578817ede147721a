"""Benchmark: the fast learner's gradient step with its two Q-network input layers, on one CPU thread.

    .venv/bin/python eval/bench_window_layer.py [--batch 256] [--steps 500] [--rounds 3] [--json docs/bench_window_layer.json]

Both networks are the fast learner's (64, 64) MLP on the 7x7 window of block codes and the 7 state
values. ``one_hot``: ``OneHotWindow`` expands the codes to the 497-wide one-hot input and the first
``Linear`` multiplies it. ``codes``: ``WindowLayer`` computes that layer from the codes (a lookup of 49
weight rows forward, the dense product backward). A step is what SB3's ``DQN.train`` does per gradient
step: the target network on the next observations, the online network, the Huber loss, backward,
gradient clipping and a fused Adam step. Also timed: the action choice for 32 envs (one forward pass).
The two are timed in alternation, ``--rounds`` times, on observations the vector env painted.
"""

from __future__ import annotations

import argparse
import json
import time
from pathlib import Path

import numpy as np
import torch
import torch.nn.functional as F
from _provenance import provenance  # eval/_provenance.py: command, date, machine, commit
from torch import nn

from garage_mj.generation.vec_env import GarageGenVecEnv
from garage_mj.generation.window_net import OneHotWindow, WindowLayer


def network(kind: str, vec: GarageGenVecEnv) -> nn.Module:
    space, actions = vec.observation_space, int(vec.action_space.n)
    if kind == "one_hot":
        first = OneHotWindow(space)
        return nn.Sequential(first, nn.Linear(first.features_dim, 64), nn.ReLU(), nn.Linear(64, 64), nn.ReLU(),
                             nn.Linear(64, actions))
    return nn.Sequential(WindowLayer(space, 64), nn.Linear(64, 64), nn.ReLU(), nn.Linear(64, actions))


def painted_observations(vec: GarageGenVecEnv, n: int) -> torch.Tensor:
    vec.seed(0)
    rng, obs = np.random.default_rng(0), [vec.reset()]
    while sum(len(o) for o in obs) < n:
        obs.append(vec.step(rng.integers(0, vec.action_space.n, vec.num_envs))[0])
    return torch.as_tensor(np.concatenate(obs)[:n])


def time_kind(kind: str, vec: GarageGenVecEnv, obs: torch.Tensor, batch: int, steps: int) -> dict[str, float]:
    torch.manual_seed(0)
    net, target = network(kind, vec), network(kind, vec)
    opt = torch.optim.Adam(net.parameters(), lr=1e-3, fused=True)
    rng = np.random.default_rng(0)
    batches = [(obs[rng.integers(0, len(obs), batch)], obs[rng.integers(0, len(obs), batch)],
                torch.as_tensor(rng.integers(0, vec.action_space.n, (batch, 1))), torch.rand(batch, 1))
               for _ in range(16)]

    def step(i: int) -> None:
        o, o2, a, r = batches[i % len(batches)]
        with torch.no_grad():
            y = r + 0.99 * target(o2).max(dim=1, keepdim=True).values
        loss = F.smooth_l1_loss(net(o).gather(1, a), y)
        opt.zero_grad()
        loss.backward()
        nn.utils.clip_grad_norm_(net.parameters(), 10.0)
        opt.step()

    for i in range(50):
        step(i)
    t0 = time.perf_counter()
    for i in range(steps):
        step(i)
    train_ms = (time.perf_counter() - t0) / steps * 1e3
    act = obs[:32]
    with torch.no_grad():
        t0 = time.perf_counter()
        for _ in range(steps):
            net(act).argmax(dim=1)
        act_ms = (time.perf_counter() - t0) / steps * 1e3
    return {"train_step_ms": train_ms, "act_32_ms": act_ms}


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--batch", type=int, default=256, help="transitions per gradient step (the fast learner's)")
    ap.add_argument("--steps", type=int, default=500, help="timed gradient steps per kind and round")
    ap.add_argument("--rounds", type=int, default=3)
    ap.add_argument("--json", type=Path, help="also write the figures here, with their provenance")
    args = ap.parse_args()
    prov = provenance()
    torch.set_num_threads(1)
    vec = GarageGenVecEnv("m5_13x13_aligned", 32, window="codes")
    obs = painted_observations(vec, 4096)
    rows = []
    print(f"gradient step at batch {args.batch} and action choice for 32 envs, one thread (ms)")
    for rnd in range(args.rounds):
        for kind in ("one_hot", "codes"):
            r = {"round": rnd, "input_layer": kind, **time_kind(kind, vec, obs, args.batch, args.steps)}
            rows.append(r)
            print(f"round {rnd}  {kind:<8} train step {r['train_step_ms']:.3f}  act {r['act_32_ms']:.3f}", flush=True)
    summary = {k: {m: float(np.median([r[m] for r in rows if r["input_layer"] == k]))
                   for m in ("train_step_ms", "act_32_ms")} for k in ("one_hot", "codes")}
    summary["train_step_speedup"] = round(summary["one_hot"]["train_step_ms"] / summary["codes"]["train_step_ms"], 2)
    print(f"median train step: one_hot {summary['one_hot']['train_step_ms']:.3f} ms, codes "
          f"{summary['codes']['train_step_ms']:.3f} ms ({summary['train_step_speedup']}x)")
    if args.json:
        args.json.parent.mkdir(parents=True, exist_ok=True)
        args.json.write_text(json.dumps({"batch": args.batch, "steps": args.steps, "summary": summary, "runs": rows,
                                         "provenance": prov}, indent=1) + "\n")
        print(f"wrote {args.json}")


if __name__ == "__main__":
    main()
