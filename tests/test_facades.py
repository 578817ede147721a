"""The lazy stage facades (``garage_mj.scene``, ``garage_mj.export``): every public name loads, nothing loads early."""

from __future__ import annotations

import importlib
import subprocess
import sys

import pytest

FACADES = ("garage_mj.scene", "garage_mj.export")


@pytest.mark.parametrize("package", FACADES)
def test_every_public_name_of_a_facade_resolves(package):
    mod = importlib.import_module(package)
    assert mod.__all__, package
    for name in mod.__all__:
        assert getattr(mod, name) is not None, f"{package}.{name}"
    with pytest.raises(AttributeError, match="no attribute 'nope'"):
        mod.nope  # noqa: B018


def test_the_readme_imports_work():
    from garage_mj.export import export_pack, load_pack, write_xodr  # noqa: F401
    from garage_mj.scene import GarageScene, build_scene, lane_graph, route  # noqa: F401


def test_importing_a_facade_imports_none_of_its_modules():
    code = ("import sys, garage_mj.scene, garage_mj.export\n"
            "print(sorted(m for m in sys.modules if m.startswith(('garage_mj.scene.', 'garage_mj.export.'))))\n")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True)
    assert out.stdout.strip() == "[]"
