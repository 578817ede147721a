"""Initial maps: the ``maps/*.txt`` format (docs/spec.md section 2) and the shipped maps.

Format: one grid row per line, whitespace-separated block codes, ``#`` starts a comment. The
shipped maps live in the package data ``garage_mj.maps`` and are found through
``importlib.resources``, never through the current directory.
"""

from __future__ import annotations

from dataclasses import dataclass
from importlib import resources
from pathlib import Path

import numpy as np

from garage_mj.core.errors import printable
from garage_mj.grid.blocks import Axis
from garage_mj.grid.garage import MAX_SIDE, Garage, MapError, validate_initial

MAP_SUFFIX = ".txt"


@dataclass(frozen=True)
class MapInfo:
    name: str
    rows: int
    cols: int
    description: str


def _map_dir():
    return resources.files("garage_mj.maps")


def list_maps() -> list[MapInfo]:
    """The shipped maps, sorted by name."""
    out = []
    for entry in sorted(_map_dir().iterdir(), key=lambda p: p.name):
        if entry.name.endswith(MAP_SUFFIX):
            text = entry.read_text()
            grid, description = parse_map_text(text, entry.name)
            out.append(MapInfo(entry.name[: -len(MAP_SUFFIX)], grid.shape[0], grid.shape[1], description))
    return out


def parse_map_text(text: str, source: str = "map") -> tuple[np.ndarray, str]:
    """Parse the text format into an int8 grid; returns (grid, description from leading comments).

    Validates only the syntax (tokens, ragged rows, emptiness); :func:`validate_initial` checks
    the rules.
    """
    if "\x00" in text:
        raise MapError(f"{source}: binary file, not a text map; maps are rows of codes 0-9")
    rows: list[list[int]] = []
    description: list[str] = []
    for lineno, raw in enumerate(text.splitlines(), start=1):
        line, _, comment = raw.partition("#")
        if not rows and not line.strip() and comment.strip():
            description.append(comment.strip())
        tokens = line.split()
        if not tokens:
            continue
        row = []
        for col, tok in enumerate(tokens):
            if len(tok) != 1 or tok not in "0123456789":  # not str.isdigit(): "²" is a digit to it
                raise MapError(
                    f"{source}, line {lineno} (row {len(rows)}), column {col}: bad token {tok!r}; "
                    "cells are single codes 0-9 separated by spaces"
                )
            row.append(int(tok))
        if rows and len(row) != len(rows[0]):
            raise MapError(
                f"{source}, line {lineno} (row {len(rows)}): ragged row with {len(row)} cells, "
                f"the first row has {len(rows[0])}"
            )
        rows.append(row)
        if len(rows) > MAX_SIDE or len(row) > MAX_SIDE:
            raise MapError(f"{source}, line {lineno}: the map is larger than {MAX_SIDE}x{MAX_SIDE} cells, "
                           "the largest supported")
    if not rows:
        raise MapError(f"{source}: the map is empty; write one row of codes per line")
    return np.array(rows, dtype=np.int8), " ".join(description)


def _resolve(name_or_path: str | Path) -> tuple[str, str, str]:
    """Return (name, source label, text) for a shipped name or a file path."""
    p = Path(name_or_path)
    shipped = _map_dir().joinpath(f"{name_or_path}{MAP_SUFFIX}") if isinstance(name_or_path, str) else None
    if shipped is not None and "/" not in str(name_or_path) and shipped.is_file():
        return str(name_or_path), f"map {name_or_path!r}", shipped.read_text()
    if p.is_file():
        try:
            raw = p.read_bytes()
        except OSError as exc:
            raise MapError(f"{p}: cannot read the map file: {exc.strerror}") from None
        if b"\x00" in raw:
            raise MapError(f"{p}: binary file, not a text map; maps are rows of codes 0-9")
        try:
            text = raw.decode("utf-8")
        except UnicodeDecodeError:
            raise MapError(f"{p}: not UTF-8 text; maps are rows of codes 0-9") from None
        name = p.name[: -len(MAP_SUFFIX)] if p.name.endswith(MAP_SUFFIX) else p.name
        return name, str(p), text
    names = ", ".join(m.name for m in list_maps())
    raise MapError(f"no map named or at {str(name_or_path)!r}; shipped maps: {names}")


def load_map(name_or_path: str | Path, six_stall_axis: Axis = "NS") -> Garage:
    """Load a shipped map by name (``"tiny_7x11"``) or a map file; returns an unpainted Garage."""
    name, source, text = _resolve(name_or_path)
    grid, _ = parse_map_text(text, source)
    validate_initial(grid, source)
    try:
        return Garage.from_initial(grid, name=name, six_stall_axis=six_stall_axis)
    except MapError as exc:  # the name (the file's stem) is too long or holds a control character
        raise MapError(f"{printable(source)}: {exc}; rename the file") from None
