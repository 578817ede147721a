"""Loading typed configuration objects (docs/spec.md: every number is a default living in one config).

Each config is a frozen dataclass that lives beside the code it configures (for example
:class:`garage_mj.grid.metrics.DifficultyConfig`, :class:`garage_mj.grid.reward.RewardConfig`).
``load_config(cls, mapping_or_path)`` builds one from a dict or a TOML file and rejects unknown
keys, so a typo never passes silently, and every value of the wrong type, NaN or infinite, or outside
the :class:`Bounds` its field declares (``iterations: int = bounded(6, ge=1)``), with one line that names
the file, the key, the value and the allowed range. :func:`refuse_other_settings` is the check every resumable
job makes before it continues in a folder: the settings stored there must be the ones asked for now.
"""

from __future__ import annotations

import dataclasses
import functools
import json
import math
import sys
import typing
from collections.abc import Callable, Iterable, Mapping
from dataclasses import dataclass
from pathlib import Path
from typing import Any, TypeVar

from garage_mj.core.words import a_noun

if sys.version_info >= (3, 11):
    import tomllib
else:  # Python 3.10: the same parser from PyPI
    import tomli as tomllib

from garage_mj.core.errors import GarageMJError

T = TypeVar("T")


class ConfigError(GarageMJError, ValueError):
    """A configuration file or mapping is malformed (unknown key, wrong type)."""


#: The ``metadata`` key of a dataclass field that holds its :class:`Bounds`.
BOUNDS = "bounds"


@dataclass(frozen=True)
class Bounds:
    """The values a config field may take beyond its type, declared next to the field with :func:`bounded`.

    A number's range (``ge``/``gt``/``le``/``lt``; for a tuple field, each item's), a tuple's item count
    (``length`` exactly, or at least ``min_items``) and a string's ``choices``. :func:`load_config`
    checks them for every config class, so a bad value is refused with the file, key, value and range.
    """

    ge: float | None = None
    gt: float | None = None
    le: float | None = None
    lt: float | None = None
    length: int | None = None
    min_items: int | None = None
    choices: tuple[str, ...] | None = None
    why: str = ""  # why the range is what it is, said after it in the error

    def allows(self, value: Any) -> bool:
        """Whether ``value`` (already of the field's type) is inside these bounds."""
        if isinstance(value, (tuple, list)):
            if self.length is not None and len(value) != self.length:
                return False
            if self.min_items is not None and len(value) < self.min_items:
                return False
            return all(self._allows_one(v) for v in value)
        return self._allows_one(value)

    def _allows_one(self, v: Any) -> bool:
        if self.choices is not None:
            return v in self.choices
        return ((self.ge is None or v >= self.ge) and (self.gt is None or v > self.gt)
                and (self.le is None or v <= self.le) and (self.lt is None or v < self.lt))

    def range_text(self) -> str:
        """The range in words: ``in [0, 1]``, ``>= 1``, ``one of a, b`` ('' when unbounded)."""
        if self.choices is not None:
            return "one of " + ", ".join(self.choices)
        lo, lo_open = (self.gt, True) if self.gt is not None else (self.ge, False)
        hi, hi_open = (self.lt, True) if self.lt is not None else (self.le, False)
        if lo is not None and hi is not None:
            return f"in {'(' if lo_open else '['}{_num(lo)}, {_num(hi)}{')' if hi_open else ']'}"
        if lo is not None:
            return f"{'>' if lo_open else '>='} {_num(lo)}"
        if hi is not None:
            return f"{'<' if hi_open else '<='} {_num(hi)}"
        return ""


def _num(x: float) -> str:
    return f"{int(x):_}" if float(x).is_integer() else repr(x)  # 1_000_000, as TOML may write it


def bounded(default: Any, *, ge: float | None = None, gt: float | None = None, le: float | None = None,
            lt: float | None = None, length: int | None = None, min_items: int | None = None,
            choices: tuple[str, ...] | None = None, why: str = "") -> Any:
    """A dataclass field with ``default`` and :class:`Bounds` that :func:`load_config` checks
    (``iterations: int = bounded(6, ge=1)``)."""
    bounds = Bounds(ge=ge, gt=gt, le=le, lt=lt, length=length, min_items=min_items, choices=choices, why=why)
    return dataclasses.field(default=default, metadata={BOUNDS: bounds})


_NOUNS = {int: ("an integer", "integers"), float: ("a finite number", "finite numbers"), bool: ("true or false", "true/false"),
          str: ("a string", "strings")}


def allowed(tp: Any, bounds: Bounds | None = None) -> str:
    """What a field of type ``tp`` within ``bounds`` must be, in words (``a list of 3 integers >= 1``)."""
    bounds = bounds or Bounds()
    rng = bounds.range_text()
    if typing.get_origin(tp) is tuple:
        args = typing.get_args(tp)
        item = args[0]
        count = bounds.length if bounds.length is not None else (len(args) if args[-1] is not Ellipsis else None)
        plural = _NOUNS.get(item, ("a value", "values"))[1]
        if count is not None:
            head = f"a list of {count} {plural}"
        elif bounds.min_items:
            head = (f"a non-empty list of {plural}" if bounds.min_items == 1
                    else f"a list of at least {bounds.min_items} {plural}")
        else:
            head = f"a list of {plural}"
        text = f"{head}, each {rng}" if rng else head
    elif bounds.choices is not None:
        text = rng
    else:
        noun = _NOUNS.get(tp, ("a value", "values"))[0]
        text = f"{noun} {rng}" if rng else noun
    return f"{text} ({bounds.why})" if bounds.why else text


class _Bad(Exception):
    """A value that is not of its field's type (turned into one :class:`ConfigError` line by the caller)."""


def _finite(value: Any) -> bool:
    """No float anywhere inside ``value`` is NaN or infinite."""
    if isinstance(value, float):
        return math.isfinite(value)
    if isinstance(value, (list, tuple)):
        return all(_finite(v) for v in value)
    if isinstance(value, dict):
        return all(_finite(v) for v in value.values())
    return True


def _coerce(value: Any, tp: Any) -> Any:
    """``value`` as type ``tp`` (ints to floats, lists to tuples); :class:`_Bad` when it is not one, or holds
    a NaN or an infinity anywhere."""
    if not _finite(value):
        raise _Bad("not finite")
    origin = typing.get_origin(tp)
    if origin is dict:
        if not isinstance(value, dict):
            raise _Bad("expected a table")
        ktp, vtp = typing.get_args(tp)
        return {_coerce(k, ktp): _coerce(v, vtp) for k, v in value.items()}
    if origin is tuple:
        args = typing.get_args(tp)
        if not isinstance(value, (list, tuple)):
            raise _Bad("expected a list")
        if args[-1] is Ellipsis:
            return tuple(_coerce(v, args[0]) for v in value)
        if len(value) != len(args):
            raise _Bad(f"expected {len(args)} items")
        return tuple(_coerce(v, t) for v, t in zip(value, args))
    if tp is float:
        if isinstance(value, bool) or not isinstance(value, (int, float)):
            raise _Bad("expected a number")
        return float(value)
    if tp is int:
        if isinstance(value, bool):
            raise _Bad("expected an integer")
        if isinstance(value, str) and value.lstrip("-").isdigit():
            return int(value)  # TOML table keys are strings
        if not isinstance(value, int):
            raise _Bad("expected an integer")
        return value
    if tp is bool:
        if not isinstance(value, bool):
            raise _Bad("expected true/false")
        return value
    if tp is str:
        if not isinstance(value, str):
            raise _Bad("expected a string")
        return value
    return value  # Optional/Union/Literal and friends: trusted as given (but finite)


def _toml(value: Any) -> str:
    """``value`` as a TOML file spells it (``true``, ``inf``, ``"a"``, ``[1, 2]``)."""
    if isinstance(value, bool):
        return "true" if value else "false"
    if isinstance(value, float) and not math.isfinite(value):
        return str(value)  # nan, inf, -inf
    if isinstance(value, str):
        return json.dumps(value)
    if isinstance(value, (list, tuple)):
        return "[" + ", ".join(_toml(v) for v in value) + "]"
    if isinstance(value, dict):
        return "{" + ", ".join(f"{k} = {_toml(v)}" for k, v in value.items()) + "}"
    return repr(value)


def _shown(value: Any) -> str:
    """``value`` as the config file spells it, cut to one short line."""
    text = _toml(value)
    return text if len(text) <= 80 else text[:77] + "..."


@functools.cache
def _fields(cls: type) -> dict[str, tuple[Any, Bounds | None]]:
    """Each field of config ``cls``: its type and its :class:`Bounds` (None: only the type is checked)."""
    hints = typing.get_type_hints(cls)
    return {f.name: (hints[f.name], f.metadata.get(BOUNDS)) for f in dataclasses.fields(cls)}


def checked_value(cls: type, name: str, value: Any, where: str) -> Any:
    """Field ``name`` of config ``cls`` set to ``value``, coerced to the field's type and checked against its
    :class:`Bounds`; anything else (wrong type, NaN or infinity, out of range) is one :class:`ConfigError`
    line naming ``where`` (the file), the key, the value and what is allowed."""
    tp, bounds = _fields(cls)[name]
    try:
        value = _coerce(value, tp)
        ok = bounds is None or bounds.allows(value)
    except _Bad:
        ok = False
    if not ok:
        raise ConfigError(f"{where}: {name} = {_shown(value)} is not allowed: {name} must be {allowed(tp, bounds)}")
    return value


def check_bounds(config: Any, where: str | None = None) -> None:
    """Refuse a config instance with a field outside its type or :class:`Bounds` (for ``__post_init__``: a
    config built in code is held to the ranges a loaded one is)."""
    for f in dataclasses.fields(config):
        checked_value(type(config), f.name, getattr(config, f.name), where or type(config).__name__)


def read_toml(path: str | Path, what: str = "config file") -> dict[str, Any]:
    """Parse a TOML file; a missing or malformed file is a :class:`ConfigError` naming it."""
    path = Path(path)
    try:
        return tomllib.loads(path.read_text())
    except FileNotFoundError:
        raise ConfigError(f"{what} {path} does not exist") from None
    except (tomllib.TOMLDecodeError, UnicodeDecodeError) as exc:
        raise ConfigError(f"{path} is not valid TOML: {exc}") from None
    except RecursionError:
        raise ConfigError(f"{path} is not {a_noun(what)}: TOML nested too deeply") from None
    except OSError as exc:
        raise ConfigError(f"cannot read {what} {path}: {exc.strerror}") from None


def load_config(cls: type[T], source: dict[str, Any] | str | Path | None = None, *, where: str | Path | None = None,
                **overrides: Any) -> T:
    """Build config ``cls`` from a mapping or a TOML file, plus keyword overrides.

    Unknown keys raise :class:`ConfigError` naming the key and the known ones. Every value is checked
    against its field's type and :class:`Bounds` (:func:`checked_value`; NaN and infinities are refused
    everywhere): a bad one is one line naming the file (``source`` when it is a path, else ``where``, else
    the class; an override is named by the class), the key, the value and the allowed range.
    """
    data: dict[str, Any] = {}
    origin = str(where) if where is not None else cls.__name__
    if isinstance(source, (str, Path)):
        origin = str(source)
        data = read_toml(source)
    elif source is not None:
        data = dict(source)
    data.update(overrides)
    known = {f.name for f in dataclasses.fields(cls)}
    unknown = sorted(set(data) - known)
    if unknown:
        raise ConfigError(
            f"{origin}: unknown key(s) {', '.join(unknown)}; known keys: {', '.join(sorted(known))}"
        )
    kwargs = {k: checked_value(cls, k, v, cls.__name__ if k in overrides else origin) for k, v in data.items()}
    try:
        return cls(**kwargs)
    except ValueError as exc:  # a check across fields in the class's __post_init__: named by the file too
        if origin == cls.__name__ and isinstance(exc, ConfigError):
            raise
        raise ConfigError(str(exc) if origin == cls.__name__ else f"{origin}: {exc}") from None


def to_dict(config: Any) -> dict[str, Any]:
    """A plain dict of a config dataclass (for manifests and logs)."""
    return dataclasses.asdict(config)


def settings_diff(stored: Mapping[str, Any], wanted: Mapping[str, Any],
                  keys: Iterable[str] | None = None) -> list[str]:
    """The keys whose values differ between ``stored`` and ``wanted`` (a missing key reads as None):
    in the order of ``keys`` when given, else all keys of either, sorted."""
    names = sorted(set(stored) | set(wanted)) if keys is None else list(keys)
    return [k for k in names if stored.get(k) != wanted.get(k)]


def refuse_other_settings(stored: Mapping[str, Any], wanted: Mapping[str, Any],
                          refuse: Callable[[list[str]], Exception], keys: Iterable[str] | None = None) -> None:
    """Raise ``refuse(differing keys)`` unless the settings ``stored`` in a run folder are those ``wanted`` now.

    A job that resumes in a folder must not mix its results with another settings' ones; ``refuse``
    builds the job's own error from the keys :func:`settings_diff` names. ``wanted`` is compared as
    JSON would store it (tuples as lists), since ``stored`` was read back from a JSON file. With
    ``keys``, only those are compared; without, the whole mappings are, so a key that one side lacks
    and the other holds as None refuses too (no name shows it).
    """
    wanted = json.loads(json.dumps(wanted))
    diff = settings_diff(stored, wanted, keys)
    if diff or (keys is None and stored != wanted):
        raise refuse(diff)
