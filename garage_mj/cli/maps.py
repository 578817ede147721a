"""``garage-mj maps list|validate|show``: the shipped initial maps and checking your own."""

from __future__ import annotations

import argparse

from garage_mj.core.errors import printable
from garage_mj.grid.garage import MapError
from garage_mj.grid.map_io import list_maps, load_map
from garage_mj.grid.text import draw


def register(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser("maps", help="list, show and validate initial maps")
    msub = p.add_subparsers(dest="maps_command", metavar="ACTION", required=True)
    ls = msub.add_parser("list", help="list the shipped maps")
    ls.set_defaults(func=_list)
    v = msub.add_parser("validate", help="check map files; one line per file, non-zero exit if any is bad")
    v.add_argument("files", nargs="+", metavar="FILE", help="map files (or shipped names)")
    v.set_defaults(func=_validate)
    s = msub.add_parser("show", help="draw a map as text")
    s.add_argument("map", help="shipped map name or map file")
    s.set_defaults(func=_show)


def _list(args: argparse.Namespace) -> int:
    maps = list_maps()
    width = max(len(m.name) for m in maps)
    for m in maps:
        print(f"{m.name:<{width}}  {m.rows:>2}x{m.cols:<2}  {m.description}")
    return 0


def _validate(args: argparse.Namespace) -> int:
    bad = 0
    for f in args.files:
        try:
            g = load_map(f)
        except MapError as exc:
            print(f"INVALID {printable(str(exc))}")
            bad += 1
        else:
            h, w = g.shape
            print(f"OK      {f}: {h}x{w}, entrance {g.entrance}, exit {g.exit}")
    return 1 if bad else 0


def _show(args: argparse.Namespace) -> int:
    print(draw(load_map(args.map).grid, legend=True))
    return 0
