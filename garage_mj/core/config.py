"""Loading typed configuration objects (SPEC: every number is a default living in one config).

Each config is a frozen dataclass that lives beside the code it configures (for example
:class:`garage_mj.grid.metrics.DifficultyConfig`, :class:`garage_mj.grid.reward.RewardConfig`).
``load_config(cls, mapping_or_path)`` builds one from a dict or a TOML file and rejects unknown
keys, so a typo never passes silently. :func:`refuse_other_settings` is the check every resumable
job makes before it continues in a folder: the settings stored there must be the ones asked for now.
"""

from __future__ import annotations

import dataclasses
import json
import sys
import typing
from collections.abc import Callable, Iterable, Mapping
from pathlib import Path
from typing import Any, TypeVar

if sys.version_info >= (3, 11):
    import tomllib
else:  # Python 3.10: the same parser from PyPI
    import tomli as tomllib

from garage_mj.core.errors import GarageMJError

T = TypeVar("T")


class ConfigError(GarageMJError, ValueError):
    """A configuration file or mapping is malformed (unknown key, wrong type)."""


def _coerce(value: Any, tp: Any, where: str) -> Any:
    origin = typing.get_origin(tp)
    if origin is dict:
        if not isinstance(value, dict):
            raise ConfigError(f"{where}: expected a table, got {value!r}")
        ktp, vtp = typing.get_args(tp)
        return {_coerce(k, ktp, where): _coerce(v, vtp, where) for k, v in value.items()}
    if tp is float:
        if isinstance(value, bool) or not isinstance(value, (int, float)):
            raise ConfigError(f"{where}: expected a number, got {value!r}")
        return float(value)
    if tp is int:
        if isinstance(value, bool):
            raise ConfigError(f"{where}: expected an integer, got {value!r}")
        if isinstance(value, str) and value.lstrip("-").isdigit():
            return int(value)  # TOML table keys are strings
        if not isinstance(value, int):
            raise ConfigError(f"{where}: expected an integer, got {value!r}")
        return value
    if tp is bool:
        if not isinstance(value, bool):
            raise ConfigError(f"{where}: expected true/false, got {value!r}")
        return value
    if tp is str:
        if not isinstance(value, str):
            raise ConfigError(f"{where}: expected a string, got {value!r}")
        return value
    return value  # Optional/Union/Literal and friends: trusted as given


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
        raise ConfigError(f"{path} is not a {what}: TOML nested too deeply") from None
    except OSError as exc:
        raise ConfigError(f"cannot read {what} {path}: {exc.strerror}") from None


def load_config(cls: type[T], source: dict[str, Any] | str | Path | None = None, **overrides) -> T:
    """Build config ``cls`` from a mapping or a TOML file, plus keyword overrides.

    Unknown keys raise :class:`ConfigError` naming the key and the known ones.
    """
    data: dict[str, Any] = {}
    where = cls.__name__
    if isinstance(source, (str, Path)):
        where = str(source)
        data = read_toml(source)
    elif source is not None:
        data = dict(source)
    data.update(overrides)
    hints = typing.get_type_hints(cls)
    known = {f.name for f in dataclasses.fields(cls)}
    unknown = sorted(set(data) - known)
    if unknown:
        raise ConfigError(
            f"{where}: unknown key(s) {', '.join(unknown)}; known keys: {', '.join(sorted(known))}"
        )
    kwargs = {k: _coerce(v, hints[k], f"{where}: {k}") for k, v in data.items()}
    return cls(**kwargs)


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
