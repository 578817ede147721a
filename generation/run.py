"""Run a generation protocol: every (map, seed) run, one scenario library, the figures.

    .venv/bin/python generation/run.py generation/smoke.toml --out runs/smoke
    .venv/bin/python generation/run.py generation/paper.toml --scale 0.01 --workers 2 --out runs/paper_1pct
    .venv/bin/python generation/run.py generation/smoke.toml --workers 2 --backend ray --out runs/smoke_ray
    .venv/bin/python generation/run.py generation/paper.toml --backend ray --address HEAD:6379 --workers 16 --out runs/paper
    .venv/bin/python generation/run.py generation/paper.toml --status --out runs/paper

Finished runs are skipped and interrupted ones resumed, so after a crash start the same command
again; --status prints where each run stands (from any shell, while it runs or after). Logic lives
in :mod:`garage_mj.generation.protocol` (the runs), :mod:`garage_mj.generation.progress` (the view)
and :mod:`garage_mj.reporting.experiment` (runs, then figures).
"""

from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path

from garage_mj.core.backends import Compute
from garage_mj.core.errors import GarageMJError
from garage_mj.generation.progress import format_progress, protocol_progress
from garage_mj.generation.protocol import load_protocol
from garage_mj.generation.training import DEFAULT_LEARNER, LEARNERS
from garage_mj.reporting.experiment import run_experiment


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("config", type=Path, help="protocol TOML (generation/paper.toml, generation/smoke.toml)")
    ap.add_argument("--learner", choices=sorted(LEARNERS),
                    help="DQN settings of every run (garage_mj.generation.training.LEARNERS); default: the file's "
                         f"[experiment] learner, else {DEFAULT_LEARNER}")
    ap.add_argument("--scale", type=float, default=1.0, help="multiply the timesteps per run (0 < SCALE <= 1)")
    ap.add_argument("--workers", type=int, default=1, help="runs trained at a time (processes, or Ray CPUs)")
    ap.add_argument("--backend", choices=("local", "ray"), default="local",
                    help="local: this process or a process pool (default); ray: --workers runs at a time as Ray "
                         "tasks on any node of the cluster at --address (else a private local Ray), streaming their "
                         "garages and checkpoints to this process, which alone writes --out (pip install 'garage-mj[ray]')")
    ap.add_argument("--address", metavar="HOST:PORT", help="with --backend ray: a running Ray cluster, e.g. HOST:6379")
    ap.add_argument("--out", type=Path, help="output folder (default: runs/<protocol name>)")
    ap.add_argument("--no-progress", action="store_true", help="no progress bars")
    ap.add_argument("--status", action="store_true",
                    help="print where each run stands (status, timesteps, garages, timesteps/s) and exit; trains nothing")
    args = ap.parse_args(argv)
    try:
        protocol = load_protocol(args.config, learner=args.learner)
        if args.scale != 1.0:
            protocol = protocol.scaled(args.scale)
        out = args.out or Path("runs") / protocol.name
        title = (f"{protocol.name}: {len(protocol.maps)} map(s) x {len(protocol.seeds)} seed(s) x "
                 f"{protocol.timesteps} timesteps -> {out}")
        if args.status:
            print(format_progress(protocol_progress(protocol, out), title))
            return 0
        print(format_progress(protocol_progress(protocol, out), title) if not args.no_progress else title, flush=True)
        compute = Compute(workers=args.workers, backend=args.backend, address=args.address,
                          progress=not args.no_progress)
        summary = run_experiment(protocol, out, compute=compute)
    except GarageMJError as exc:  # a bad config, map, library, run folder, backend ...: one line
        print(f"run.py: error: {exc}", file=sys.stderr)
        return 2
    except KeyboardInterrupt:
        print("run.py: interrupted; run the same command again to resume", file=sys.stderr)
        return 130
    print(json.dumps(summary, indent=2))
    return 0


if __name__ == "__main__":
    sys.exit(main())
