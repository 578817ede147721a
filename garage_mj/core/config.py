"""Loading typed configuration objects (SPEC: every number is a default living in one config).

Each config is a frozen dataclass that lives beside the code it configures (for example
:class:`garage_mj.grid.metrics.DifficultyConfig`, :class:`garage_mj.grid.reward.RewardConfig`).
``load_config(cls, mapping_or_path)`` builds one from a dict or a TOML file and rejects unknown
keys, so a typo never passes silently.
"""

from __future__ import annotations

import dataclasses
import sys
import typing
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
