"""Helpers shared by the subcommands: argument types, library filters, and the :class:`Compute` of a command."""

from __future__ import annotations

import argparse
import functools
import math
import os
from collections.abc import Callable, Iterable
from pathlib import Path
from typing import Any

from garage_mj.cli import UserError
from garage_mj.core.backends import Compute
from garage_mj.core.errors import GarageMJError
from garage_mj.scene.route_difficulty import load_route_model
from garage_mj.scene.world import (
    DEFAULT_WORLD,
    GEOMETRY_KEYS,
    GeometryError,
    WorldConfig,
    geometry,
    load_layout,
    world_with,
)


def user_errors(func: Callable[[argparse.Namespace], int]) -> Callable[[argparse.Namespace], int]:
    """Turn a ``ValueError`` raised by a library call on user input into a one-line :class:`UserError`.

    Every garage-mj error (``TrainingError`` and ``DriverError`` included) is a
    :class:`GarageMJError` already and passes through unchanged.
    """

    @functools.wraps(func)
    def wrapper(args: argparse.Namespace) -> int:
        try:
            return func(args)
        except GarageMJError:
            raise
        except ValueError as exc:  # e.g. an empty range given to Library.query
            raise UserError(str(exc)) from None

    return wrapper


def compute(args: argparse.Namespace) -> Compute:
    """How a command runs its jobs, from its ``--workers``, ``--backend``, ``--address`` and ``--quiet`` (or
    ``--no-progress``) flags; a flag the command does not have takes :class:`Compute`'s default."""
    quiet = getattr(args, "quiet", False) or getattr(args, "no_progress", False)
    return Compute(workers=getattr(args, "workers", 1), backend=getattr(args, "backend", "local"),
                   address=getattr(args, "address", None), progress=not quiet)


#: The most garages a --limit or -n counts (a library of the paper's full protocol holds about 500,000).
MAX_ROWS = 1_000_000_000
#: The most worker processes a --workers starts.
MAX_WORKERS = 1024


def unit_range(text: str) -> float:
    """argparse type: a number in [0, 1]."""
    try:
        x = float(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"{text!r} is not a number") from None
    if not 0.0 <= x <= 1.0:
        raise argparse.ArgumentTypeError(f"{text} is outside [0, 1]")
    return x


def _int_at_least(text: str, low: int, problem: str) -> int:
    try:
        n = int(text.replace("_", ""))  # 2_000_000 reads like the TOML protocols
    except ValueError:
        raise argparse.ArgumentTypeError(f"{text!r} is not an integer") from None
    if n < low:
        raise argparse.ArgumentTypeError(f"{text} {problem}")
    return n


def non_negative_int(text: str) -> int:
    """argparse type: an integer >= 0."""
    return _int_at_least(text, 0, "is negative")


def positive_int(text: str) -> int:
    """argparse type: an integer >= 1."""
    return _int_at_least(text, 1, "must be >= 1")


def int_in(low: int, high: int) -> Callable[[str], int]:
    """argparse type: an integer in [low, high] (``1_000`` allowed); the message names the range."""

    def parse(text: str) -> int:
        try:
            n = int(text.replace("_", ""))
        except ValueError:  # "1e12", "nan", and numbers of more than 4,300 digits
            n = None
        if n is None or not low <= n <= high:
            shown = text if len(text) <= 40 else f"{text[:20]}...({len(text)} characters)"
            raise argparse.ArgumentTypeError(f"{shown} is not allowed: give an integer from {low:,} to {high:,}")
        return n

    parse.__name__ = f"integer from {low:,} to {high:,}"
    return parse


def positive_seconds(text: str) -> float:
    """argparse type: a number of seconds > 0 (``--test-timeout``)."""
    try:
        value = float(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"{text!r} is not a number of seconds") from None
    if not math.isfinite(value) or value <= 0:
        raise argparse.ArgumentTypeError(f"{text} must be a number of seconds > 0")
    return value


def seed(text: str) -> int:
    """argparse type: a random seed, an integer in [0, 2**32) as numpy and SB3 require."""
    n = _int_at_least(text, 0, "is negative; seeds are integers from 0 to 4294967295")
    if n >= 2**32:
        raise argparse.ArgumentTypeError(f"{text} is too large; seeds are integers from 0 to 4294967295")
    return n


def seed_list(text: str) -> list[int]:
    """argparse type: comma-separated seeds (e.g. generation runs' ``0,1,2``), each >= 0, without repeats."""
    try:
        seeds = [int(v) for v in text.split(",") if v.strip()]
    except ValueError:
        seeds = []
    if not seeds or len(set(seeds)) != len(seeds) or min(seeds) < 0:
        raise argparse.ArgumentTypeError(f"{text!r}: give comma-separated seeds >= 0 without repeats (e.g. 0,1,2)")
    return seeds


#: What a ``--route-model`` help adds about the shipped models by name (``load_route_model``).
SHIPPED_ROUTE_MODELS = "'learned': the shipped learned driver's own"


def add_filters(p: argparse.ArgumentParser) -> None:
    """The library filters: --map, --difficulty LO HI, --coverage LO HI, --feasible LO HI,
    --route-difficulty LO HI (with --route-model FILE), --limit N."""
    p.add_argument("--map", help="only garages of this map (name as stored, e.g. tiny_7x11)")
    p.add_argument("--difficulty", nargs=2, type=unit_range, metavar=("LO", "HI"),
                   help="only the paper's difficulty in [LO, HI] (0-1)")
    p.add_argument("--route-difficulty", nargs=2, type=unit_range, metavar=("LO", "HI"),
                   help="only route difficulty (expected failure rate of a cruise test) in [LO, HI] (0-1), as "
                   "stored by 'garage-mj library rate LIBRARY'")
    p.add_argument("--route-model", type=Path, metavar="FILE",
                   help="route difficulty model of --route-difficulty and of the values shown (default: the shipped "
                   f"one; {SHIPPED_ROUTE_MODELS}; 'garage-mj difficulty fit' writes others), or the key "
                   "park:<model>:<geometry> that 'generate --metric park' printed, for its park difficulty")
    p.add_argument("--coverage", nargs=2, type=unit_range, metavar=("LO", "HI"),
                   help="only coverage in [LO, HI] (0-1)")
    p.add_argument("--feasible", nargs=2, type=unit_range, metavar=("LO", "HI"),
                   help="only garages whose share of stalls with a feasible cruise test is in [LO, HI] "
                   "(stored by 'garage-mj check --library FILE --store')")
    p.add_argument("--limit", type=int_in(0, MAX_ROWS), help=f"at most N garages (0 to {MAX_ROWS:,})")


#: The options that select library garages by their metrics (attribute -> flag); --ids leaves them out.
SELECTORS = {"map": "--map", "difficulty": "--difficulty", "route_difficulty": "--route-difficulty",
             "coverage": "--coverage", "feasible": "--feasible", "limit": "--limit", "sample": "--sample"}


def add_ids(p: argparse.ArgumentParser) -> None:
    """``--ids ID [ID ...]``: library garages chosen by row id (the first column of ``library ls``)."""
    p.add_argument("--ids", type=positive_int, nargs="+", metavar="ID",
                   help="with --library: exactly these garages, by row id (the first column of 'garage-mj library "
                        "ls'), in the order given; instead of the filters")


def refuse_overwriting(path: Path, flag: str, inputs: Iterable[Path | None]) -> None:
    """Refuse an output file ``flag`` names that is one of the command's ``inputs`` (the library it reads,
    a results file): writing it would destroy what the command reads."""
    if not path.exists():
        return
    for src in inputs:
        try:
            same = src is not None and src.exists() and os.path.samefile(path, src)
        except OSError:
            same = False
        if same:
            raise UserError(f"{flag} {path} is an input of this command ({src}); writing it would destroy it: "
                            "name another file")


def check_output_file(path: Path, flag: str, inputs: Iterable[Path | None] = ()) -> None:
    """Refuse, before any work, an output file ``flag`` names that cannot be written: one of ``inputs``
    (:func:`refuse_overwriting`), a folder, a folder that does not exist, a file where a folder should be,
    a folder this process may not write."""
    refuse_overwriting(path, flag, inputs)
    folder = path.parent if str(path.parent) else Path(".")
    if path.is_dir():
        raise UserError(f"{flag} {path} is a folder; name a file")
    if folder.exists() and not folder.is_dir():
        raise UserError(f"{flag} {path}: {folder} is a file, not a folder; name a file in a folder")
    if not folder.is_dir():
        raise UserError(f"{flag} {path}: the folder {folder} does not exist; make it or name a file in another one")
    if not os.access(folder, os.W_OK | os.X_OK):
        raise UserError(f"{flag} {path}: the folder {folder} is read-only; name a file in a folder you may write")


def records_by_id(lib: Any, args: argparse.Namespace) -> list:
    """The library records of ``--ids`` (each once, in the order given), checked by their hash; a filter given
    beside them, or an id the library lacks, is a one-line error."""
    given = [flag for attr, flag in SELECTORS.items() if getattr(args, attr, None) is not None]
    if given:
        raise UserError(f"--ids picks garages by row id; leave out {', '.join(given)} (or --ids, to filter)")
    return lib.verified([lib.get(i) for i in dict.fromkeys(args.ids)])


def filters(args: argparse.Namespace) -> dict:
    """The filter keyword arguments of :meth:`Library.query` from parsed ``args`` (``route_model``: the
    key of ``--route-model`` or the shipped model, when ``--route-difficulty`` is given)."""
    route = checked_range(getattr(args, "route_difficulty", None), "route-difficulty")
    return {"map": args.map, "difficulty": checked_range(args.difficulty, "difficulty"),
            "coverage": checked_range(args.coverage, "coverage"),
            "feasible": checked_range(getattr(args, "feasible", None), "feasible"),
            "route": route, "route_model": route_key(args) if route is not None else None}


def route_key(args: argparse.Namespace) -> str:
    """The key of the route difficulty model ``--route-model`` names, or of the shipped one; a park key
    (``park:<model>:<geometry>``, what ``generate --metric park`` stores its values under) as it is."""
    given = getattr(args, "route_model", None)
    if given is not None and str(given).startswith("park:"):
        return str(given)
    return load_route_model(given).key


def checked_range(rng: list[float] | None, flag: str) -> tuple[float, float] | None:
    """A parsed ``--FLAG LO HI`` as a tuple (None when not given); LO above HI is a :class:`UserError`."""
    if rng is None:
        return None
    if rng[0] > rng[1]:
        raise UserError(f"--{flag} {rng[0]} {rng[1]}: LO is above HI")
    return tuple(rng)


def add_geometry_args(p: argparse.ArgumentParser) -> None:
    """The park geometry options (docs/spec.md section 9): ``--stall-width``, ``--stall-depth``, ``--aisle-width``,
    ``--stall-angle``, ``--slot-length`` and ``--layout FILE.toml`` (the flags override the file's keys)."""
    default = geometry(DEFAULT_WORLD)
    g = p.add_argument_group("park geometry (docs/spec.md section 9; the paper's grid and metrics do not change)")
    helps = {
        "stall_width": ("M", f"stall (bay) width, 2.2 to 3.0 m (default {default['stall_width']:g})"),
        "stall_depth": ("M", f"stall depth, 4.0 to 6.0 m (default {default['stall_depth']:g}; deeper than 4.5 m "
                             "needs a narrower aisle beside six-stall blocks)"),
        "aisle_width": ("M", f"drivable width of a straight road block, 5.5 to 9.0 m (default "
                             f"{default['aisle_width']:g}: the whole block); the rest is kerb or stalls moved "
                             "toward the aisle"),
        "stall_angle": ("DEG", "stall angle to the aisle: 90 (default, perpendicular), 60 or 45 (angled: aisles "
                               "one-way from the entrance), 0 (parallel slots along the aisle)"),
        "slot_length": ("M", f"parallel slot length, 4.5 to 8.0 m (default {default['slot_length']:g}: the "
                             "sedan's length + 1 m)"),
    }
    for key in GEOMETRY_KEYS:
        metavar, text = helps[key]
        g.add_argument(f"--{key.replace('_', '-')}", dest=key, metavar=metavar, help=text)
    g.add_argument("--layout", type=Path, metavar="FILE.toml",
                   help=f"a park geometry file: keys {', '.join(GEOMETRY_KEYS)} (the options above override it)")


def geometry_world(args: argparse.Namespace) -> WorldConfig:
    """The :class:`~garage_mj.scene.world.WorldConfig` of the park geometry options (``--layout`` first, the flags
    over it); a bad value, an unknown key or a broken file is one :class:`GeometryError` line."""
    values: dict[str, Any] = {}
    if getattr(args, "layout", None) is not None:
        values.update(load_layout(str(args.layout)))
    for key in GEOMETRY_KEYS:
        text = getattr(args, key, None)
        if text is None:
            continue
        flag = f"--{key.replace('_', '-')}"
        try:
            value = float(text)
        except ValueError:
            raise GeometryError(f"{flag} {text!r} is not a number; give metres (degrees for --stall-angle)") from None
        values[key] = value
    return world_with(values, where="park geometry")
