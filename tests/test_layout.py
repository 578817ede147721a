"""The package is shaped like the pipeline: imports flow downstream only, and no two files import each other.

The stages, in pipeline order: ``core`` < ``grid`` < ``generation`` < ``scene`` < ``export`` <
``driving`` < ``reporting`` < ``testing`` < ``cli``; ``garage_mj/__init__.py`` and ``__main__.py`` sit on top.
A module may import its own stage and the stages before it. An import inside a function
(deferred) must only keep start-up light: its target, or what it imports at module level, pulls
in a heavy third-party package (``HEAVY``); a deferred import of a light module only hides a
circle, and fails here. Every failure names the file, the line and the rule.
"""

from __future__ import annotations

import ast
from pathlib import Path

import pytest

PACKAGE = Path(__file__).resolve().parents[1] / "garage_mj"
STAGES = ("core", "grid", "generation", "scene", "export", "driving", "reporting", "testing", "cli")
TOP = len(STAGES)  # garage_mj/__init__.py and __main__.py: the public API over every stage
#: Third-party packages slow enough to import that a module may defer importing what pulls them in.
HEAVY = frozenset({"torch", "stable_baselines3", "matplotlib", "mujoco", "dm_control", "ray", "trimesh",
                   "cv2", "scenariogeneration", "lxml", "scipy", "networkx", "gymnasium", "imageio", "selenium"})


def _module_name(path: Path) -> str:
    parts = list(path.relative_to(PACKAGE.parent).with_suffix("").parts)
    return ".".join(parts[:-1] if parts[-1] == "__init__" else parts)


def _modules() -> dict[str, Path]:
    return {_module_name(p): p for p in sorted(PACKAGE.rglob("*.py"))}


def _stage(module: str) -> int:
    parts = module.split(".")
    return STAGES.index(parts[1]) if len(parts) > 1 and parts[1] in STAGES else TOP


class _Import:
    def __init__(self, source: str, target: str, line: int, deferred: bool, typing_only: bool) -> None:
        self.source, self.target, self.line = source, target, line
        self.deferred, self.typing_only = deferred, typing_only

    def where(self, modules: dict[str, Path]) -> str:
        return f"{modules[self.source].relative_to(PACKAGE.parent)}:{self.line}"


def _imports(modules: dict[str, Path]) -> tuple[list[_Import], dict[str, set[str]]]:
    """Internal imports of every module, and the third-party top-level names each imports at module level."""
    found, external = [], {}
    for name, path in modules.items():
        package = name if path.name == "__init__.py" else name.rpartition(".")[0]
        external[name] = set()

        def visit(node: ast.AST, deferred: bool, typing_only: bool, name=name, package=package) -> None:
            for child in ast.iter_child_nodes(node):
                d = deferred or isinstance(child, (ast.FunctionDef, ast.AsyncFunctionDef, ast.Lambda))
                t = typing_only or (isinstance(child, ast.If) and "TYPE_CHECKING" in ast.unparse(child.test))
                targets: list[str] = []
                if isinstance(child, ast.Import):
                    targets = [a.name for a in child.names]
                elif isinstance(child, ast.ImportFrom):
                    base = child.module or ""
                    if child.level:
                        up = package.split(".")[: len(package.split(".")) - child.level + 1]
                        base = ".".join(up + ([child.module] if child.module else []))
                    targets = [f"{base}.{a.name}" if f"{base}.{a.name}" in modules else base for a in child.names]
                for target in dict.fromkeys(targets):
                    if target.split(".")[0] == "garage_mj":
                        found.append(_Import(name, target, child.lineno, d, t))
                    elif not d and not t:
                        external[name].add(target.split(".")[0])
                visit(child, d, t)

        visit(ast.parse(path.read_text(), str(path)), False, False)
    return found, external


MODULES = _modules()
IMPORTS, EXTERNAL = _imports(MODULES)


def test_top_level_holds_only_the_stages():
    top = {p.name for p in PACKAGE.iterdir() if not p.name.startswith((".", "__pycache__"))}
    assert top == {"__init__.py", "__main__.py", *STAGES}, f"garage_mj/ should hold the stages only: {sorted(top)}"


def test_imports_flow_downstream():
    bad = [f"{i.where(MODULES)} imports {i.target} ({STAGES[_stage(i.target)] if _stage(i.target) < TOP else 'the top package'}) "
           f"from the earlier stage {STAGES[_stage(i.source)]}"
           for i in IMPORTS if _stage(i.source) < TOP and _stage(i.target) > _stage(i.source)]
    bad += [f"{i.where(MODULES)} imports the top package garage_mj: import from the stage that defines the name"
            for i in IMPORTS if i.target == "garage_mj" and _stage(i.source) < TOP]
    assert not bad, "imports against the pipeline:\n" + "\n".join(bad)


def _heavy(module: str, seen: set[str] | None = None) -> bool:
    """Whether importing ``module`` imports a HEAVY package (its module-level imports, transitively)."""
    seen = set() if seen is None else seen
    if module in seen or module not in MODULES:
        return False
    seen.add(module)
    if EXTERNAL[module] & HEAVY:
        return True
    return any(_heavy(i.target, seen) for i in IMPORTS if i.source == module and not i.deferred and not i.typing_only)


def test_deferred_imports_only_keep_start_up_light():
    bad = [f"{i.where(MODULES)} defers importing {i.target}, which imports nothing heavy: import it at the top"
           for i in IMPORTS if i.deferred and i.target in MODULES and not _heavy(i.target)]
    assert not bad, "deferred imports that only hide a circle:\n" + "\n".join(bad)


def _cycles() -> list[list[str]]:
    """Strongly connected components of more than one file (Tarjan), over every non-typing import."""
    graph: dict[str, set[str]] = {m: set() for m in MODULES}
    for i in IMPORTS:
        if not i.typing_only and i.target in MODULES and i.target != i.source:
            graph[i.source].add(i.target)
    index: dict[str, int] = {}
    low: dict[str, int] = {}
    stack: list[str] = []
    on_stack: set[str] = set()
    out: list[list[str]] = []

    def strong(v: str) -> None:
        index[v] = low[v] = len(index)
        stack.append(v)
        on_stack.add(v)
        for w in graph[v]:
            if w not in index:
                strong(w)
                low[v] = min(low[v], low[w])
            elif w in on_stack:
                low[v] = min(low[v], index[w])
        if low[v] == index[v]:
            comp = []
            while True:
                w = stack.pop()
                on_stack.discard(w)
                comp.append(w)
                if w == v:
                    break
            if len(comp) > 1:
                out.append(sorted(comp))

    for v in graph:
        if v not in index:
            strong(v)
    return out


def test_no_import_circles():
    lines = []
    for comp in _cycles():
        inside = [i for i in IMPORTS if i.source in comp and i.target in comp and not i.typing_only]
        lines.append(" <-> ".join(comp) + ": " + "; ".join(f"{i.where(MODULES)} imports {i.target}" for i in inside))
    assert not lines, "import circles between files:\n" + "\n".join(lines)


@pytest.mark.parametrize("stage", STAGES)
def test_every_stage_documents_its_modules(stage):
    """Each stage's ``__init__`` docstring names every module in it, so the tree explains itself."""
    init = PACKAGE / stage / "__init__.py"
    doc = ast.get_docstring(ast.parse(init.read_text())) or ""
    missing = [p.stem for p in sorted((PACKAGE / stage).iterdir())
               if p.suffix == ".py" and not p.name.startswith("_") and f"``{p.stem}``" not in doc]
    missing += [p.name for p in sorted((PACKAGE / stage).iterdir())
                if p.is_dir() and (p / "__init__.py").exists() and f"``{p.name}``" not in doc]
    assert not missing, f"garage_mj/{stage}/__init__.py does not describe: {', '.join(missing)}"


def _make_plan(target: str) -> str:
    """The commands ``make TARGET`` would run on a fresh clone (``-n -B``: print, run nothing, all out of date)."""
    import shutil
    import subprocess

    if shutil.which("make") is None:
        pytest.skip("no make on this machine")
    root = Path(__file__).resolve().parents[1]
    return subprocess.run(["make", "-n", "-B", "-C", str(root), target], capture_output=True, text=True,
                          check=True).stdout


def test_make_demo_installs_only_what_the_demo_runs():
    demo, test = _make_plan("demo"), _make_plan("test")
    assert "-m pip install -q --no-compile -e ." in demo and "garage-mj demo" in demo
    for tests_only in (".venv-blender", ".venv-qc", "[dev", "carla", "chromium"):
        assert tests_only not in demo and tests_only in test
    assert "-m pip install -q --no-compile -e '.[dev,ray,carla]'" in test and "pytest" in test  # the package, with the test tools
