"""The garage model: an encoding matrix plus the initial map it was painted on.

A :class:`Garage` is the unit every stage passes along: the generation env produces one, the
library stores one, the exporters turn one into asset packs, the cruise tests drive in one.
"""

from __future__ import annotations

import hashlib
import json
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from garage_mj.core.errors import GarageMJError, control_character
from garage_mj.grid.blocks import AXES, INITIAL_CODES, NUM_CODES, STALL_CODES, Axis, Block
from garage_mj.grid.road_segments import analyse
from garage_mj.grid.rules import expected_cell, road_squares, stall_rule_violations

MAX_SIDE = 64  # [cells] rows or columns of a map or garage (576 m at 9 m per cell); bounds memory and time
MAX_NAME = 128  # [characters] of a garage name (it becomes part of a pack's folder name)


class MapError(GarageMJError, ValueError):
    """A map or garage breaks a rule of docs/spec.md section 2. The message names where and which."""


def _where(source: str, r: int | None = None, c: int | None = None) -> str:
    if r is None:
        return source
    if c is None:
        return f"{source}, row {r}"
    return f"{source}, row {r}, column {c}"


def find_gates(grid: np.ndarray, source: str = "map") -> tuple[tuple[int, int], tuple[int, int]]:
    """Locate and validate the ENTRANCE and EXIT of ``grid``; returns their (row, col).

    Rules (docs/spec.md section 2): exactly one of each, on the outer ring but not in a corner, each with
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
    """Raise :class:`MapError` unless ``grid`` is a valid initial map (docs/spec.md section 2)."""
    if grid.ndim != 2 or grid.size == 0:
        raise MapError(f"{source}: the map is empty; write one row of codes per line")
    h, w = grid.shape
    if h < 3 or w < 3:
        raise MapError(f"{source}: the map is {h}x{w}; it needs at least 3 rows and 3 columns")
    if h > MAX_SIDE or w > MAX_SIDE:
        raise MapError(f"{source}: the map is {h}x{w}; at most {MAX_SIDE} rows and {MAX_SIDE} columns are supported")
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


@dataclass(frozen=True)
class _LongInteger:
    """A JSON integer too long to be a block code, kept as its digits: Python refuses to convert one
    of over 4,300 digits, and no cell needs more than one."""

    digits: str


def _parse_int(digits: str) -> int | _LongInteger:
    """``json.loads``'s ``parse_int``: an integer, or a :class:`_LongInteger` for one of over 20 digits."""
    return int(digits) if len(digits) <= 20 else _LongInteger(digits)


def decode_json(text: str | bytes, source: str = "garage JSON") -> Any:
    """The decoded JSON of a garage file (integers of over 20 digits kept as text for the messages); a file that
    is not JSON is a :class:`MapError` naming ``source``."""
    try:
        return json.loads(text, parse_int=_parse_int)
    except (json.JSONDecodeError, UnicodeDecodeError) as exc:
        raise MapError(f"{source} is not valid JSON: {exc}") from None
    except RecursionError:
        raise MapError(f"{source} is not a garage: JSON nested too deeply") from None


def grid_hash(grid: np.ndarray, six_stall_axis: str) -> str:
    """:meth:`Garage.canonical_hash` of a garage with ``grid`` and ``six_stall_axis``: SHA-256 of shape, axis
    and block codes (a reader that holds only the grid checks a stored hash with it)."""
    h = hashlib.sha256()
    h.update(f"{grid.shape[0]}x{grid.shape[1]}:{six_stall_axis}:".encode())
    h.update(np.ascontiguousarray(grid, dtype=np.int8).tobytes())
    return h.hexdigest()


def _shown(v: Any) -> str:
    """A cell's value as the message quotes it (a long integer by its first digits and its length)."""
    if isinstance(v, _LongInteger):
        return f"{v.digits[:8]}... ({len(v.digits.lstrip('-'))} digits)"
    return json.dumps(v)[:20]


def _code_rows(rows: Any, where: str) -> np.ndarray:
    """A JSON list of rows of block codes as an int8 array; strict: no strings, floats, booleans."""
    if not isinstance(rows, list) or not rows or not all(isinstance(r, list) for r in rows):
        raise MapError(f"{where} must be a non-empty list of rows (lists of block codes 0-{NUM_CODES - 1})")
    if len(rows) > MAX_SIDE or any(len(r) > MAX_SIDE for r in rows):
        raise MapError(f"{where} is larger than {MAX_SIDE}x{MAX_SIDE} cells, the largest supported garage")
    if any(len(r) != len(rows[0]) for r in rows):
        raise MapError(f"{where} is ragged, not rectangular; every row needs {len(rows[0])} cells")
    for r, row in enumerate(rows):
        for c, v in enumerate(row):
            if type(v) is not int or not 0 <= v < NUM_CODES:
                raise MapError(f"{where}, row {r}, column {c}: {_shown(v)} is not a block code "
                               f"(an integer 0-{NUM_CODES - 1})")
    return np.array(rows, dtype=np.int8)


def validate_garage(garage: Garage, source: str | None = None) -> Garage:
    """Raise :class:`MapError` unless ``garage`` can be exported and driven; returns it.

    The one check of a whole garage, used by export and cruise (:class:`Garage` itself already
    enforces the shape limits, the codes, the gates and the fixed cells when it is built): the
    stall rule holds everywhere, no 2x2 square of road-like cells, and the entrance reaches the
    exit on road. The message names the first offending cell and the fix.
    """
    src = source or f"garage {garage.name!r}"
    for r, c in stall_rule_violations(garage.grid, garage.six_stall_axis)[:1]:
        want = expected_cell(garage.grid, r, c, garage.six_stall_axis)
        raise MapError(f"{_where(src, r, c)}: {Block(int(garage.grid[r, c])).name} breaks the stall rule "
                       f"(it must be {want.name}); recolour stalls with garage_mj.grid.rules.apply_stall_rule")
    for r, c in road_squares(garage.grid)[:1]:
        raise MapError(f"{_where(src, r, c)}: a 2x2 square of road starts here (rows {r}-{r + 1}, columns "
                       f"{c}-{c + 1}); roads must not form 2x2 squares")
    if not analyse(garage.grid).connected(garage.entrance, garage.exit):
        raise MapError(f"{src}: no road joins the entrance {garage.entrance} to the exit {garage.exit}; "
                       "only a connected garage can be exported or driven")
    return garage


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
        if not isinstance(self.name, str) or len(self.name) > MAX_NAME:
            raise MapError(f"garage name {str(self.name)[:40]!r}... is longer than {MAX_NAME} characters; "
                           "give it a shorter name")
        bad = control_character(self.name)
        if bad is not None:
            raise MapError(f"garage name {self.name[:40]!r} holds the control character {bad!r}; "
                           "give it a name of printable characters")
        src = f"garage {self.name!r}"
        for what in ("grid", "initial"):
            arr = np.asarray(getattr(self, what))
            if arr.ndim != 2 or arr.dtype.kind not in "iu" or ((arr < 0) | (arr >= NUM_CODES)).any():
                raise MapError(f"{src}: {what} must be a 2-D array of block codes 0-{NUM_CODES - 1}")
            setattr(self, what, arr.astype(np.int8))
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

    @classmethod
    def painted(cls, grid: np.ndarray, initial: np.ndarray, six_stall_axis: Axis, name: str,
                entrance: tuple[int, int], exit: tuple[int, int]) -> Garage:
        """A garage the painter env made on a map it validated: the same object the constructor builds,
        without its checks (the painter changes only FREE cells into road and stall codes). ``grid`` and
        ``initial`` are int8 arrays the garage now owns."""
        garage = cls.__new__(cls)
        garage.grid, garage.initial, garage.six_stall_axis, garage.name = grid, initial, six_stall_axis, name
        garage.entrance, garage.exit = entrance, exit
        return garage

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
    def from_json(cls, text: str | bytes | dict[str, Any], source: str = "garage JSON", *,
                  usable: bool = False) -> Garage:
        """Inverse of :meth:`to_json`; accepts the JSON text or the decoded dict.

        Always checks the shape limits, the codes (JSON integers 0-9), gates and fixed cells;
        ``usable=True`` also applies :func:`validate_garage` (what export and cruise need).
        """
        data = text if isinstance(text, dict) else decode_json(text, source)
        if not isinstance(data, dict):
            raise MapError(f"{source}: expected an object with name, grid, initial, six_stall_axis")
        missing = [k for k in ("grid", "initial") if k not in data]
        if missing:
            raise MapError(f"{source}: missing key(s) {', '.join(missing)}")
        grid = _code_rows(data["grid"], f"{source}: grid")
        initial = _code_rows(data["initial"], f"{source}: initial")
        name = data.get("name", "garage")
        if not isinstance(name, str):
            raise MapError(f"{source}: name must be a string, not {type(name).__name__}")
        axis = data.get("six_stall_axis", "NS")
        if not isinstance(axis, str):
            raise MapError(f"{source}: six_stall_axis must be 'NS' or 'EW'")
        try:
            garage = cls(grid, initial, six_stall_axis=axis, name=name)  # type: ignore[arg-type]
        except MapError as exc:
            raise MapError(f"{source}: {exc}") from None
        return validate_garage(garage, source) if usable else garage

    def canonical_hash(self) -> str:
        """SHA-256 of shape, grid and six-stall axis: equal garages hash equal (:func:`grid_hash`)."""
        return grid_hash(self.grid, self.six_stall_axis)

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
