"""``garage-mj train``: DQN on the generation env; usable garages go into the scenario library."""

from __future__ import annotations

import argparse
from pathlib import Path

from garage_mj.cli import UserError
from garage_mj.cli._common import int_in, positive_int, seed, user_errors
from garage_mj.core.fsutil import FolderLock

ALGOS = ("dqn",)
MAX_TIMESTEPS = 1_000_000_000  # of one run (a shipped protocol run is 2,000,000; 1e9 is days of training)
LEARNER_NAMES = ("fast", "paper")  # garage_mj.generation.training.LEARNERS, named here so --help stays light


def register(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser(
        "train",
        help="train DQN on a map; usable garages go into the scenario library",
        description=(
            "Train stable-baselines3 DQN on the garage-painting env of one map. Every usable garage "
            "met during training is committed to the library at once (with run, seed, episode and "
            "timestep), so an interrupted run loses none. The run folder gets run.json (manifest, "
            "throughput), monitor.csv (episode returns, for 'garage-mj plot convergence') and "
            "checkpoints/; Ctrl-C saves a checkpoint, --resume continues from the newest one."
        ),
        epilog="example: garage-mj train --map tiny_7x11 --timesteps 20000 --seed 0 --out runs/tiny_s0",
    )
    p.add_argument("--map", required=True, help="shipped map name (garage-mj maps list) or map file")
    p.add_argument("--timesteps", required=True, type=int_in(1, MAX_TIMESTEPS),
                   help=f"total timesteps of the run (1 to {MAX_TIMESTEPS:,})")
    p.add_argument("--seed", type=seed, default=0, help="random seed of the run (default 0)")
    p.add_argument("--out", required=True, type=Path, help="run folder (must be new unless --resume)")
    p.add_argument("--algo", default="dqn", choices=ALGOS, help="RL algorithm (default: dqn)")
    p.add_argument("--resume", action="store_true", help="continue the run in --out from its newest checkpoint")
    p.add_argument("--learner", choices=LEARNER_NAMES, default=None,
                   help="DQN settings to start from: fast (the default: 32 garages painted at once, a (64, 64) "
                        "Q-network, 3-step returns; about 13x the timesteps/s of paper, more garages per run) or "
                        "paper (one env, (256, 256), one gradient step per 4 timesteps, as the paper trains); "
                        "--config keys override them")
    p.add_argument("--config", type=Path, help="TOML file of DQN hyper-parameters (keys of DQNConfig; unknown keys are an error)")
    p.add_argument("--library", type=Path, help="library file (default: OUT/library.sqlite)")
    p.add_argument("--checkpoint-every", type=positive_int, metavar="N", help="timesteps between checkpoints (overrides the config)")
    p.add_argument("--no-progress", action="store_true", help="no progress bar")
    p.set_defaults(func=run)


@user_errors
def run(args: argparse.Namespace) -> int:
    from garage_mj.generation.training import DEFAULT_LEARNER, load_dqn_config, train

    overrides = {"checkpoint_every": args.checkpoint_every} if args.checkpoint_every else {}
    if args.config is not None and not args.config.is_file():
        raise UserError(f"config file {args.config} does not exist")
    if args.resume and args.config is None and (overrides or args.learner):
        raise UserError("--checkpoint-every and --learner cannot change a resumed run; drop them or start a new --out")
    learner = args.learner or DEFAULT_LEARNER
    config = load_dqn_config(args.config, learner=learner, **overrides) if (args.config or overrides or not args.resume) else None
    with FolderLock(args.out, "garage-mj train", remove=True):  # a second run into the same --out is refused
        m = train(args.map, args.timesteps, args.seed, args.out, config=config, resume=args.resume,
                  library_path=args.library, progress=not args.no_progress)
    s = m.get("last_session")
    print(f"run {m['run']}: {m['timesteps']} timesteps, {m['episodes']} episodes, "
          f"{m['garages_stored']} garages in {m['library']}")
    if s and s["timesteps"]:
        print(f"this run: {s['timesteps']} timesteps in {s['wall_s']:.1f} s = {s['timesteps_per_s']:.0f} "
              f"timesteps/s, env {100 * s['env_share']:.1f}% of the time, {s['usable_episodes']} usable "
              f"episodes, {s['garages_stored']} new garages")
    else:
        print(f"{args.out} had already finished {m['timesteps']} timesteps; nothing to do")
    r = m.get("returns")
    if r:
        print(f"learning: mean episode return {r['first_mean']:.1f} over the first {r['window']} episodes, "
              f"{r['last_mean']:.1f} over the last {r['window']} (a tenth of {r['episodes']} each; higher is better)")
    return 0
