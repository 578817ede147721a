"""``garage-mj show ID``: one garage of the library as text and, with --png, as a picture."""

from __future__ import annotations

import argparse
from pathlib import Path

from garage_mj.cli._common import user_errors
from garage_mj.generation.library import Library
from garage_mj.grid.text import draw

DEFAULT_LIBRARY = Path("library.sqlite")


def register(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser(
        "show",
        help="draw a library garage as text and optionally as a PNG",
        description="Prints a garage of the library as text (with metrics) and, with --png, writes a "
        "top-down picture: a colour per block code, a legend, and the road graph drawn over it.",
    )
    p.add_argument("id", type=int, help="garage id (see 'garage-mj library ls')")
    p.add_argument("--library", type=Path, default=DEFAULT_LIBRARY, help="library file (default: ./library.sqlite)")
    p.add_argument("--png", type=Path, metavar="FILE", help="also write a top-down picture to FILE")
    p.set_defaults(func=run)


@user_errors
def run(args: argparse.Namespace) -> int:
    from garage_mj.reporting.plots import garage_png

    with Library(args.library, create=False) as lib:
        r = lib.get(args.id)
    g = r.garage
    print(f"garage {r.id} of {r.map} (run {r.run}, episode {r.episode}, timestep {r.timestep}): "
          f"difficulty {r.difficulty:.3f}, coverage {r.coverage:.3f}, {r.stalls} stalls")
    print(draw(g.grid, legend=True))
    if args.png is not None:
        title = f"{r.map} #{r.id}: difficulty {r.difficulty:.3f}, coverage {r.coverage:.3f}, {r.stalls} stalls"
        print(f"picture -> {garage_png(g, args.png, title=title)}")
    return 0
