"""The garage model: an encoding matrix plus the initial map it was painted on.

A :class:`Garage` is the unit every stage passes along: the generation env produces one, the
library stores one, the exporters turn one into asset packs, the cruise tests drive in one.
"""

from __future__ import annotations

import hashlib
import json
from dataclasses import dataclass, field
from typing import Any, Literal

import numpy as np

from garage_mj.blocks import INITIAL_CODES, NUM_CODES, STALL_CODES, Block
from garage_mj.errors import GarageMJError

Axis = Literal["NS", "EW"]
AXES: tuple[Axis, ...] = ("NS", "EW")


class MapError(GarageMJError, ValueError):
    """A map or garage breaks a rule of SPEC section 2. The message names where and which."""


def _where(source: str, r: int | None = None, c: int | None = None) -> str:
    if r is None:
        return source
    if c is None:
        return f"{source}, row {r}"
    return f"{source}, row {r}, column {c}"


def find_gates(grid: np.ndarray, source: str = "map") -> tuple[tuple[int, int], tuple[int, int]]:
    """Locate and validate the ENTRANCE and EXIT of ``grid``; returns their (row, col).

    Rules (SPEC section 2): exactly one of each, on the outer ring but not in a corner, each with
    exactly one in-grid neighbour that is not OBSTACLE.
    """
    h, w = grid.shape
    gates = {}
    for code in (Block.ENTRANCE, Block.EXIT):
        cells = [tuple(int(x) for x in rc) for rc in np.argwhere(grid == code)]
        name = code.name.lower()
        if not cells:
            raise MapError(f"{source}: no {name} (code {int(code)}); a map needs exactly one")
        if len(cells) > 1:
            where = "; ".join(f"row {r}, column {c}" for r, c in cells)
            raise MapError(f"{source}: {len(cells)} {name}s ({where}); a map needs exactly one")
        r, c = cells[0]
        on_ring = r in (0, h - 1) or c in (0, w - 1)
        corner = r in (0, h - 1) and c in (0, w - 1)
        if not on_ring:
            raise MapError(
                f"{_where(source, r, c)}: {name} is inside the grid; gates must lie on the outer ring"
            )
        if corner:
            raise MapError(
                f"{_where(source, r, c)}: {name} is in a corner; put it on an edge, not a corner"
            )
        open_ = [
            (rr, cc)
            for rr, cc in ((r - 1, c), (r + 1, c), (r, c - 1), (r, c + 1))
            if 0 <= rr < h and 0 <= cc < w and grid[rr, cc] != Block.OBSTACLE
        ]
        if not open_:
            raise MapError(
                f"{_where(source, r, c)}: {name} is sealed (every neighbour is an obstacle); "
                "free the cell next to it"
            )
        if len(open_) > 1:
            raise MapError(
                f"{_where(source, r, c)}: {name} opens onto {len(open_)} cells; "
                "it needs exactly one non-obstacle neighbour (make the ring cells beside it obstacles)"
            )
        gates[code] = (r, c)
    return gates[Block.ENTRANCE], gates[Block.EXIT]


def validate_initial(grid: np.ndarray, source: str = "map") -> None:
    """Raise :class:`MapError` unless ``grid`` is a valid initial map (SPEC section 2)."""
    if grid.ndim != 2 or grid.size == 0:
        raise MapError(f"{source}: the map is empty; write one row of codes per line")
    h, w = grid.shape
    if h < 3 or w < 3:
        raise MapError(f"{source}: the map is {h}x{w}; it needs at least 3 rows and 3 columns")
    for r, c in np.argwhere((grid < 0) | (grid >= NUM_CODES)):
        raise MapError(f"{_where(source, r, c)}: {grid[r, c]} is not a block code (0-9)")
    for r, c in np.argwhere(~np.isin(grid, list(INITIAL_CODES))):
        code = Block(int(grid[r, c]))
        kind = "stall code" if code in STALL_CODES else "code"
        raise MapError(
            f"{_where(source, r, c)}: {kind} {int(code)} ({code.name}) in an initial map; "
            "initial maps hold only 0 FREE, 2 OBSTACLE, 7 ENTRANCE, 8 EXIT"
        )
    find_gates(grid, source)


@dataclass
class Garage:
    """An encoding matrix (``grid``) painted on an initial map (``initial``)."""

    grid: np.ndarray
    initial: np.ndarray
    six_stall_axis: Axis = "NS"
    name: str = "garage"
    entrance: tuple[int, int] = field(init=False)
    exit: tuple[int, int] = field(init=False)

    def __post_init__(self) -> None:
        self.grid = np.asarray(self.grid, dtype=np.int8)
        self.initial = np.asarray(self.initial, dtype=np.int8)
        src = f"garage {self.name!r}"
        if self.six_stall_axis not in AXES:
            raise MapError(f"{src}: six_stall_axis must be 'NS' or 'EW', not {self.six_stall_axis!r}")
        validate_initial(self.initial, f"{src} (initial map)")
        if self.grid.shape != self.initial.shape:
            raise MapError(
                f"{src}: grid is {self.grid.shape[0]}x{self.grid.shape[1]} but the initial map is "
                f"{self.initial.shape[0]}x{self.initial.shape[1]}"
            )
        for r, c in np.argwhere((self.grid < 0) | (self.grid >= NUM_CODES)):
            raise MapError(f"{_where(src, r, c)}: {self.grid[r, c]} is not a block code (0-9)")
        fixed = np.isin(self.initial, [Block.OBSTACLE, Block.ENTRANCE, Block.EXIT])
        changed = fixed & (self.grid != self.initial)
        for r, c in np.argwhere(changed):
            raise MapError(
                f"{_where(src, r, c)}: fixed cell {Block(int(self.initial[r, c])).name} became "
                f"{Block(int(self.grid[r, c])).name}; obstacles and gates never change"
            )
        for r, c in np.argwhere(~fixed & np.isin(self.grid, [Block.OBSTACLE, Block.ENTRANCE, Block.EXIT])):
            raise MapError(
                f"{_where(src, r, c)}: {Block(int(self.grid[r, c])).name} where the initial map is FREE"
            )
        self.entrance, self.exit = find_gates(self.initial, src)

    @property
    def shape(self) -> tuple[int, int]:
        return self.grid.shape  # type: ignore[return-value]

    @classmethod
    def from_initial(cls, initial: np.ndarray, name: str = "garage", six_stall_axis: Axis = "NS") -> Garage:
        """An unpainted garage: the grid equals the initial map."""
        initial = np.asarray(initial, dtype=np.int8)
        return cls(initial.copy(), initial, six_stall_axis=six_stall_axis, name=name)

    def to_json(self) -> str:
        """``{"name", "grid", "initial", "six_stall_axis"}`` as a JSON string."""
        return json.dumps(self.to_dict())

    def to_dict(self) -> dict[str, Any]:
        return {
            "name": self.name,
            "grid": self.grid.tolist(),
            "initial": self.initial.tolist(),
            "six_stall_axis": self.six_stall_axis,
        }

    @classmethod
    def from_json(cls, text: str | bytes | dict[str, Any], source: str = "garage JSON") -> Garage:
        """Inverse of :meth:`to_json`; accepts the JSON text or the decoded dict."""
        if isinstance(text, dict):
            data = text
        else:
            try:
                data = json.loads(text)
            except (json.JSONDecodeError, UnicodeDecodeError) as exc:
                raise MapError(f"{source} is not valid JSON: {exc}") from None
        if not isinstance(data, dict):
            raise MapError(f"{source}: expected an object with name, grid, initial, six_stall_axis")
        missing = [k for k in ("grid", "initial") if k not in data]
        if missing:
            raise MapError(f"{source}: missing key(s) {', '.join(missing)}")
        try:
            grid = np.array(data["grid"], dtype=np.int64)
            initial = np.array(data["initial"], dtype=np.int64)
        except (ValueError, TypeError):
            raise MapError(f"{source}: grid and initial must be rectangular lists of integer rows") from None
        if grid.ndim != 2 or initial.ndim != 2:
            raise MapError(f"{source}: grid and initial must be rectangular lists of integer rows")
        for arr, what in ((grid, "grid"), (initial, "initial")):
            if ((arr < 0) | (arr >= NUM_CODES)).any():
                raise MapError(f"{source}: {what} holds codes outside 0-9")
        return cls(
            grid,
            initial,
            six_stall_axis=data.get("six_stall_axis", "NS"),
            name=str(data.get("name", "garage")),
        )

    def canonical_hash(self) -> str:
        """SHA-256 of shape, grid and six-stall axis: equal garages hash equal."""
        h = hashlib.sha256()
        h.update(f"{self.grid.shape[0]}x{self.grid.shape[1]}:{self.six_stall_axis}:".encode())
        h.update(np.ascontiguousarray(self.grid, dtype=np.int8).tobytes())
        return h.hexdigest()

    def to_text(self) -> str:
        """The grid as text, one row per line (the maps/ format)."""
        return "\n".join(" ".join(str(int(v)) for v in row) for row in self.grid)

    def __eq__(self, other: object) -> bool:
        if not isinstance(other, Garage):
            return NotImplemented
        return (
            self.six_stall_axis == other.six_stall_axis
            and np.array_equal(self.grid, other.grid)
            and np.array_equal(self.initial, other.initial)
        )
