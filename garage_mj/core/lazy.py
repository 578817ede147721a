"""Lazy re-exports for a stage's ``__init__``: public names that import their module on first use.

A stage package lists its public names and the submodule that defines each; importing the
package then imports none of them, so ``from garage_mj.export import write_xodr`` does not pull
in the other writers' dependencies (mujoco, trimesh, ...)::

    __getattr__, __all__ = lazy_exports(__name__, {"write_xodr": "xodr", ...})
"""

from __future__ import annotations

from collections.abc import Callable, Mapping
from importlib import import_module
from typing import Any


def lazy_exports(package: str, exports: Mapping[str, str]) -> tuple[Callable[[str], Any], list[str]]:
    """``(__getattr__, __all__)`` for ``package``: each name of ``exports`` loads from ``package.<submodule>``."""
    table = dict(exports)

    def __getattr__(name: str) -> Any:
        if name in table:
            return getattr(import_module(f"{package}.{table[name]}"), name)
        raise AttributeError(f"module {package!r} has no attribute {name!r}")

    return __getattr__, sorted(table)
