"""The wheel ships every package and data file, and setuptools has nothing to warn about.

setuptools warns ("Package would be ignored") for every folder with files that is not listed in
``packages``; these checks read ``pyproject.toml`` instead of building a wheel, so they stay fast.
"""

from __future__ import annotations

import fnmatch
from pathlib import Path

import tomllib

ROOT = Path(__file__).resolve().parents[1]
SETUP = tomllib.loads((ROOT / "pyproject.toml").read_text())["tool"]["setuptools"]


def _folder(package: str) -> Path:
    """The source folder of a dotted package name under ``package-dir``."""
    best = max((k for k in SETUP["package-dir"] if package == k or package.startswith(k + ".")), key=len)
    rest = package[len(best):].lstrip(".")
    return ROOT / SETUP["package-dir"][best] / Path(*rest.split(".")) if rest else ROOT / SETUP["package-dir"][best]


def _source_folders() -> dict[str, Path]:
    """Every folder that holds files to ship, by dotted package name."""
    out = {}
    for top, folder in SETUP["package-dir"].items():
        for d in [ROOT / folder, *sorted(p for p in (ROOT / folder).rglob("*") if p.is_dir())]:
            if d.name == "__pycache__" or not any(f.is_file() and f.suffix != ".pyc" for f in d.iterdir()):
                continue
            rel = d.relative_to(ROOT / folder)
            out[".".join([top, *rel.parts])] = d
    return out


def test_every_folder_is_a_listed_package():
    missing = sorted(set(_source_folders()) - set(SETUP["packages"]))
    assert not missing, f"add to [tool.setuptools] packages in pyproject.toml: {missing}"
    for name in SETUP["packages"]:
        assert _folder(name).is_dir(), f"packages lists {name}, but {_folder(name)} does not exist"


def test_every_data_file_ships():
    patterns = SETUP["package-data"]
    unshipped = []
    for name, folder in _source_folders().items():
        for f in folder.iterdir():
            if not f.is_file() or f.suffix in {".py", ".pyc"}:
                continue
            if not any(fnmatch.fnmatch(f.name, p) for p in patterns.get(name, [])):
                unshipped.append(str(f.relative_to(ROOT)))
    assert not unshipped, f"not matched by [tool.setuptools.package-data]: {unshipped}"
