"""Draw the Results and Performance pages' plots from result files already under docs/.

    .venv/bin/python eval/plot_pages.py            # write docs/plots/*.png
    .venv/bin/python eval/plot_pages.py --check    # exit 1 if a committed plot is not what its files draw

Each plot reads only committed result files and runs nothing, so it takes seconds and draws the same
bytes from the same files with the same matplotlib (no timestamp or version in the PNG):

- ``park_by_geometry.png``: park and AVP success of the ``oracle`` and ``park_assist`` drivers per park
  geometry and car, with the geometry's level and the targets (docs/bench_park_geometry.json,
  docs/bench_park_suv.json);
- ``learners.png``: distinct usable garages and policy return per run of the ``fast`` and ``paper``
  learners on m5 and m7, every seed (docs/learner_verdict.json);
- ``drive_env_ladder.png``: the drive env's simulated seconds per wall second, from the full loop up
  to its ceiling (physics and camera alone), before and after the speed-ups (docs/bench_drive_env.json).

The pages embed them through a record's ``plot`` field (docs/data/*.toml; eval/render_pages.py).
After a result file changes, run this and eval/render_pages.py, and commit the PNGs with the pages.
"""

from __future__ import annotations

import argparse
import io
import json
import sys
from collections.abc import Callable
from pathlib import Path

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402

ROOT = Path(__file__).resolve().parents[1]
OUT = "plots"  # under docs/
DPI = 110
PNG_METADATA = {"Software": None}  # no matplotlib version in the file: the bytes depend on the data only
OK, BASELINE, OTHER = "#2a7ab9", "#e08a2c", "#8c8c8c"
GEOMETRY_LABELS = {  # bench_park.py's geometry names as the plot writes them
    "default": "today's: 2.5 m bays, 9 m aisle",
    "tight": "tight: 2.3 m bays, 6.5 m aisle",
    "angled60": "60-degree angled",
    "parallel": "parallel, 5.6 m slots",
    "parallel_short": "parallel, 5.2 m slots",
}


class PlotError(Exception):
    """A result file a plot cannot read: one sentence naming it and the fix."""


def _read(docs: Path, name: str) -> dict:
    try:
        return json.loads((docs / name).read_text())
    except (OSError, ValueError) as exc:
        raise PlotError(f"docs/{name} cannot be read ({str(exc)[:120]}): restore it or run its benchmark") from None


def _png(fig) -> bytes:
    buf = io.BytesIO()
    fig.savefig(buf, format="png", dpi=DPI, metadata=PNG_METADATA)
    plt.close(fig)
    return buf.getvalue()


def park_by_geometry(docs: Path) -> bytes:
    """Success over feasible tests per geometry (and car): oracle park, oracle AVP, park_assist park."""
    rows = []
    for name in ("bench_park_geometry.json", "bench_park_suv.json"):
        data = _read(docs, name)
        targets = data.get("targets", {})
        for s in data["sections"]:
            geometry = s["geometry"]["name"]
            label = GEOMETRY_LABELS.get(geometry, geometry)
            if s.get("vehicle", "sedan") != "sedan":
                label += f", {s['vehicle']}"
            levels = "/".join(sorted(s.get("by_level", {})))
            rows.append((f"{label}\n({levels})", s["oracle_park"], s["oracle_avp"], s["park_assist_park"]))
    fig, ax = plt.subplots(figsize=(8.0, 0.62 * len(rows) + 1.3))
    height = 0.26
    series = (("oracle park", 1, OK), ("oracle AVP", 2, "#7fb3dc"), ("park_assist park", 3, BASELINE))
    for k, (what, i, colour) in enumerate(series):
        ys = [n + (k - 1) * height for n in range(len(rows))]
        values = [r[i]["success_pct"] for r in rows]
        ax.barh(ys, values, height=height, color=colour, label=what)
        for y, v, r in zip(ys, values, rows):
            ax.text(v + 0.8, y, f"{r[i]['success']}/{r[i]['feasible']}", va="center", fontsize=7)
    park_target = targets.get("oracle_park_success_pct")
    if park_target is not None:
        ax.axvline(park_target, color="black", lw=0.8, ls="--")
        ax.text(park_target, -0.55, f"oracle park target {park_target:g}% ", ha="right", va="bottom", fontsize=7)
    ax.set_yticks(range(len(rows)), [r[0] for r in rows], fontsize=8)
    ax.invert_yaxis()
    ax.set_xlim(0, 115)
    ax.set_xlabel("success over feasible tests [%] (the level of the geometry's park tests in brackets)")
    ax.set_title("Park and AVP tests by geometry: oracle against the park_assist template", fontsize=10)
    ax.legend(loc="upper center", bbox_to_anchor=(0.5, -0.1), ncol=3, fontsize=8, frameon=False)
    fig.tight_layout()
    return _png(fig)


def learners(docs: Path) -> bytes:
    """Every run of the fast and paper learners: garages stored and policy return, per map."""
    data = _read(docs, "learner_verdict.json")
    maps = list(data["maps"])
    fig, axes = plt.subplots(1, 2, figsize=(8.0, 3.4))
    for ax, (key, what) in zip(axes, (("garages", "distinct usable garages per run"),
                                      ("policy_return", "policy return at epsilon 0.05"))):
        for m, name in enumerate(maps):
            per_seed = data["maps"][name]["per_seed"]
            for j, (learner, colour) in enumerate((("paper", BASELINE), ("fast", OK))):
                values = per_seed[learner][key]
                x = m * 3 + j
                offsets = [((i % 7) - 3) * 0.06 for i in range(len(values))]  # spread the dots, no randomness
                ax.scatter([x + o for o in offsets], values, s=12, color=colour, alpha=0.8,
                           label=learner if m == 0 else None)
                mean = sum(values) / len(values)
                ax.plot([x - 0.3, x + 0.3], [mean, mean], color="black", lw=1.2)
        ax.set_xticks([m * 3 + 0.5 for m in range(len(maps))], [n.split("_")[0] for n in maps])
        ax.set_title(what, fontsize=9)
        ax.grid(axis="y", lw=0.3)
    axes[0].legend(fontsize=8, loc="lower right")
    runs = len(data["maps"][maps[0]]["per_seed"]["fast"]["garages"])
    fig.suptitle(f"The fast learner against the paper's: {runs} runs per learner and map, 200,000 timesteps "
                 "each (bar: mean)", fontsize=9)
    fig.tight_layout()
    return _png(fig)


def drive_env_ladder(docs: Path) -> bytes:
    """The drive env's speed from the full loop to its ceiling, before and after the speed-ups."""
    summary = _read(docs, "bench_drive_env.json")["summary"]
    rungs = (("full loop, vision driver", "full_sim_per_wall"), ("env without the driver", "env_sim_per_wall"),
             ("ceiling: physics + camera", "ceiling_sim_per_wall"), ("physics alone", "physics_sim_per_wall"),
             ("camera alone", "camera_sim_per_wall"))
    fig, ax = plt.subplots(figsize=(8.0, 3.2))
    height = 0.38
    for k, (tree, colour) in enumerate((("before", OTHER), ("after", OK))):
        ys = [n + (k - 0.5) * height for n in range(len(rungs))]
        values = [summary[tree][key] for _, key in rungs]
        ax.barh(ys, values, height=height, color=colour, label=f"{tree} the speed-ups")
        for y, v in zip(ys, values):
            ax.text(v + 4, y, f"{v:.0f}", va="center", fontsize=7)
    ax.set_yticks(range(len(rungs)), [r[0] for r in rungs], fontsize=8)
    ax.invert_yaxis()
    ax.set_xlim(0, max(summary["after"][key] for _, key in rungs) * 1.12)
    ax.set_xlabel("simulated s per wall s, one worker, m5_13x13_aligned")
    after = summary["after"]
    ax.set_title(f"The drive env against its ceiling: the full loop at 1/{after['ceiling_over_full']} of it",
                 fontsize=10)
    ax.legend(loc="upper right", fontsize=8)
    fig.tight_layout()
    return _png(fig)


PLOTS: dict[str, Callable[[Path], bytes]] = {
    "park_by_geometry.png": park_by_geometry,
    "learners.png": learners,
    "drive_env_ladder.png": drive_env_ladder,
}


def main(argv: list[str] | None = None) -> int:
    """Draw (or check) every plot; 0 when done, 1 with one line on what is wrong."""
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--check", action="store_true",
                    help="write nothing; exit 1 naming each plot that differs from what its files draw")
    ap.add_argument("--root", type=Path, default=ROOT, help="the repository root (default: this checkout)")
    args = ap.parse_args(argv)
    docs = args.root / "docs"
    try:
        drawn = {name: draw(docs) for name, draw in PLOTS.items()}
    except PlotError as exc:
        print(f"plot_pages: {exc}", file=sys.stderr)
        return 1
    stale = [n for n, png in drawn.items()
             if not (docs / OUT / n).is_file() or (docs / OUT / n).read_bytes() != png]
    if args.check:
        if stale:
            print(f"plot_pages: {', '.join(f'docs/{OUT}/{n}' for n in stale)} differ from what the result files "
                  "draw: run `.venv/bin/python eval/plot_pages.py` and commit the result", file=sys.stderr)
            return 1
        return 0
    (docs / OUT).mkdir(exist_ok=True)
    for name in stale:
        (docs / OUT / name).write_bytes(drawn[name])
        print(f"wrote docs/{OUT}/{name}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
