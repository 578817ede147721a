"""What the park benchmarks share: their common options and the painted garages they run on.

``bench_park.py``, ``bench_park_plan.py`` and ``bench_park_verdicts.py`` take ``--maps`` (default every shipped
map), ``--garages`` painted garages per map, ``--occupancy``, ``--seed`` and ``--out``; each paints a map's garages with
``painted_sources(map, garages, seed=seed)`` and seeds the tests of its garage ``k`` with ``seed * 1000 + k``.
:data:`GEOMETRIES` names the garage geometries they run on (docs/spec.md section 9).
"""

from __future__ import annotations

import argparse
from collections.abc import Iterator
from dataclasses import dataclass
from pathlib import Path

from garage_mj import list_maps
from garage_mj.driving.park_geometries import PARK_GEOMETRIES, ParkGeometry
from garage_mj.driving.sources import CruiseSource, painted_sources

#: The garage geometries a park benchmark may run on by name (docs/spec.md section 9; the product's table).
Geometry = ParkGeometry
GEOMETRIES = PARK_GEOMETRIES


def park_parser(description: str, garages: int, out: Path) -> argparse.ArgumentParser:
    """A parser with the options every park benchmark takes; ``garages`` and ``out`` are the script's defaults."""
    ap = argparse.ArgumentParser(description=description, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--maps", nargs="*", default=None, help="maps (default: every shipped map)")
    ap.add_argument("--garages", type=int, default=garages, help=f"painted garages per map (default {garages})")
    ap.add_argument("--occupancy", type=float, default=0.5, help="share of the other stalls with a parked car")
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--out", type=Path, default=out)
    return ap


def map_names(args: argparse.Namespace) -> list[str]:
    """The maps of ``--maps``, or every shipped map."""
    return args.maps or [m.name for m in list_maps()]


@dataclass(frozen=True)
class PaintedGarage:
    """One painted garage of a park benchmark."""

    map: str
    index: int  # among its map's painted garages
    source: CruiseSource
    seed: int  # the seed of its tests: --seed * 1000 + index


def painted_garages(args: argparse.Namespace, maps: list[str]) -> Iterator[PaintedGarage]:
    """The ``--garages`` painted garages of each of ``maps``, map by map (each map painted when reached)."""
    for m in maps:
        for k, source in enumerate(painted_sources(m, args.garages, seed=args.seed)):
            yield PaintedGarage(m, k, source, args.seed * 1000 + k)
