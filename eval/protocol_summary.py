"""Per-map figures of a finished ``generation/run.py`` protocol folder, next to the paper's statements.

    .venv/bin/python eval/protocol_summary.py runs/paper_5pct [--json docs/protocol_5pct/summary.json]
        [--copy-figures docs/protocol_5pct]

Per map: garages stored, difficulty range and 0.1 bins reached, mean coverage and the shares of
garages with coverage in [0.6, 0.8) and >= 0.8, and the mean return of each seed's last 100
episodes (mean and sd over seeds), read from the run folders' ``monitor.csv`` and the protocol's
``library.sqlite`` (sd: sample standard deviation over seeds). ``--copy-figures`` copies ``figures/*.png`` (convergence, heatmaps) beside.
``runs`` lists every run: map, seed, status, timesteps, episodes, garages credited to it, return of its last
100 episodes, its learner settings and its timesteps/s.
"""

from __future__ import annotations

import argparse
import csv
import json
import shutil
from pathlib import Path

import numpy as np

from garage_mj.generation.library import Library


def last_returns(run: Path, n: int = 100) -> float | None:
    path = run / "monitor.csv"
    if not path.is_file():
        return None
    with open(path, newline="") as f:
        next(f)  # the monitor's JSON header line
        rows = [float(r["r"]) for r in csv.DictReader(f)]
    return float(np.mean(rows[-n:])) if rows else None


def run_rows(folder: Path) -> list[dict]:
    """One row per run folder of the protocol, from its manifest and monitor log."""
    rows = []
    for manifest_path in sorted((folder / "runs").glob("*/seed_*/run.json")):
        m = json.loads(manifest_path.read_text())
        session = m.get("last_session") or {}
        cfg = m.get("config", {})
        ret = last_returns(manifest_path.parent)
        rows.append({
            "map": m["map"], "seed": m["seed"], "status": m.get("status"), "timesteps": m.get("timesteps"),
            "episodes": m.get("episodes"), "garages": m.get("garages_stored"),
            "ret_last100": None if ret is None else round(ret, 1),
            "vector_env": cfg.get("vector_env", False), "n_envs": cfg.get("n_envs", 1),
            "net_arch": cfg.get("net_arch"), "timesteps_per_s": session.get("timesteps_per_s"),
            "timesteps_per_cpu_s": session.get("timesteps_per_cpu_s"), "wall_s": session.get("wall_s"),
        })
    return rows


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("folder", type=Path)
    ap.add_argument("--json", type=Path)
    ap.add_argument("--copy-figures", type=Path)
    args = ap.parse_args()
    out = {}
    with Library(args.folder / "library.sqlite", create=False) as lib:
        for m in sorted(lib.maps()):
            pts = lib.points(map=m)  # (N, 2): difficulty, coverage
            diff, cov = pts[:, 0], pts[:, 1]
            rets = [r for r in (last_returns(p) for p in sorted((args.folder / "runs" / m).glob("seed_*")))
                    if r is not None]
            bins = sorted({min(int(d * 10), 9) for d in diff})
            out[m] = {
                "garages": int(len(pts)), "diff": [round(float(diff.min()), 2), round(float(diff.max()), 2)],
                "bins": len(bins), "cov_mean": round(float(cov.mean()), 2),
                "cov_share_06_08": round(float(((cov >= 0.6) & (cov < 0.8)).mean()), 2),
                "cov_share_ge_08": round(float((cov >= 0.8).mean()), 2),
                "ret_last100": round(float(np.mean(rets)), 1) if rets else None,
                "ret_sd": round(float(np.std(rets, ddof=1)), 1) if len(rets) > 1 else None,
                "seeds": len(rets),
            }
            print(m, out[m])
    out["runs"] = run_rows(args.folder)
    if args.json:
        args.json.parent.mkdir(parents=True, exist_ok=True)
        args.json.write_text(json.dumps(out, indent=1) + "\n")
    if args.copy_figures:
        args.copy_figures.mkdir(parents=True, exist_ok=True)
        for png in sorted((args.folder / "figures").glob("*.png")):
            shutil.copyfile(png, args.copy_figures / png.name)


if __name__ == "__main__":
    main()
