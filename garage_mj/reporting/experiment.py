"""The generation experiment end to end: a protocol's runs, then their figures.

:func:`run_experiment` trains every (map, seed) run of a protocol with
:func:`garage_mj.generation.protocol.run_protocol` (resumable: a finished run is skipped, an
interrupted one resumed), then :func:`draw_figures` draws into ``out/figures/`` the convergence
curves of the finished runs and one difficulty x coverage heatmap per map with garages
(:mod:`garage_mj.reporting.plots`). ``generation/run.py`` is its command line.
"""

from __future__ import annotations

from pathlib import Path
from typing import Any

from garage_mj.core.backends import DEFAULT_COMPUTE, Compute
from garage_mj.generation.library import Library
from garage_mj.generation.protocol import (
    LIBRARY,
    Protocol,
    protocol_folder,
    run_dir,
    run_protocol,
    run_status,
)
from garage_mj.reporting.plots import convergence, heatmap


def draw_figures(protocol: Protocol, out: Path) -> list[Path]:
    """Convergence curves of all finished runs and one heatmap per map with garages."""
    figures = out / "figures"
    runs = [run_dir(out, m, s) for m in protocol.maps for s in protocol.seeds]
    runs = [r for r in runs if (r / "monitor.csv").exists() and run_status(r, 1) != "new"]
    paths = []
    if runs:
        paths.append(convergence(runs, figures / "convergence.png", smooth=10))
    with Library(out / LIBRARY) as lib:
        for m in protocol.maps:
            name = Path(m).stem
            points = lib.points(name)
            if len(points):
                paths.append(heatmap(points, figures / f"heatmap_{name}.png", title=name))
    return paths


def run_experiment(protocol: Protocol, out: str | Path, *, compute: Compute = DEFAULT_COMPUTE) -> dict[str, Any]:
    """Train every (map, seed) of ``protocol`` not yet finished (:func:`run_protocol`), then draw the figures.

    Returns :func:`run_protocol`'s summary (runs trained and skipped, the library, garages per map,
    throughput) with the figure paths.
    """
    summary = run_protocol(protocol, out, compute=compute)
    figures = draw_figures(protocol, protocol_folder(out, compute))
    return {"trained": summary["trained"], "skipped": summary["skipped"], "library": summary["library"],
            "garages": summary["garages"], "figures": [str(f) for f in figures], "throughput": summary["throughput"]}
