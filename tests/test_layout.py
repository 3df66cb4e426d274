"""The house: layered folders, no import cycle, small modules, old paths aliased for a release."""

from __future__ import annotations

import ast
import importlib
import importlib.util
import json
import subprocess
import sys
from collections import defaultdict
from pathlib import Path

import pytest

import armreach_core
from armreach_core._compat import MOVED

ROOT = Path(armreach_core.__file__).resolve().parent
#: The house rule: a module does one thing; over this it should be split.
MAX_MODULE_LINES = 400
#: Where the backends and tasks that ship beside the core live.
DISTRIBUTIONS = [ROOT.parent / "backends", ROOT.parent / "tasks"]


def _module_name(path: Path, root: Path) -> str:
    parts = list(path.relative_to(root.parent).with_suffix("").parts)
    return ".".join(parts[:-1] if parts[-1] == "__init__" else parts)


def import_graph(root: Path) -> dict[str, set[str]]:
    """Each module of the package at ``root`` -> the package's modules it imports, anywhere in it
    (inside functions and under TYPE_CHECKING too). ``from pkg import sub`` counts as importing ``sub``."""
    modules = {_module_name(path, root): path for path in root.rglob("*.py")}
    graph: dict[str, set[str]] = defaultdict(set)
    for name, path in modules.items():
        package = name if path.name == "__init__.py" else name.rpartition(".")[0]
        for node in ast.walk(ast.parse(path.read_text())):
            if isinstance(node, ast.Import):
                targets = [alias.name for alias in node.names]
            elif isinstance(node, ast.ImportFrom):
                base = node.module or ""
                if node.level:
                    up = package.split(".")[: len(package.split(".")) - node.level + 1]
                    base = ".".join([*up, *([node.module] if node.module else [])])
                subs = [f"{base}.{alias.name}" for alias in node.names if f"{base}.{alias.name}" in modules]
                targets = subs if len(subs) == len(node.names) else [base, *subs]
            else:
                continue
            graph[name].update(t for t in targets if t in modules and t != name)
    return graph


def cycles(graph: dict[str, set[str]]) -> list[list[str]]:
    """The strongly connected components with more than one module (Tarjan)."""
    index: dict[str, int] = {}
    low: dict[str, int] = {}
    stack: list[str] = []
    found: list[list[str]] = []

    def visit(v: str) -> None:
        index[v] = low[v] = len(index)
        stack.append(v)
        for w in sorted(graph.get(v, ())):
            if w not in index:
                visit(w)
                low[v] = min(low[v], low[w])
            elif w in stack:
                low[v] = min(low[v], index[w])
        if low[v] == index[v]:
            component = []
            while True:
                w = stack.pop()
                component.append(w)
                if w == v:
                    break
            if len(component) > 1:
                found.append(sorted(component))

    for v in sorted(graph):
        if v not in index:
            visit(v)
    return found


def test_the_cycle_finder_finds_a_cycle(tmp_path: Path) -> None:
    package = tmp_path / "pkg"
    package.mkdir()
    (package / "__init__.py").write_text("")
    (package / "a.py").write_text("def f():\n    from pkg import b\n")
    (package / "b.py").write_text("from pkg.a import f\n")
    (package / "c.py").write_text("import pkg.a\n")
    assert cycles(import_graph(package)) == [["pkg.a", "pkg.b"]]


def test_the_core_has_no_import_cycle_counting_imports_inside_functions() -> None:
    assert cycles(import_graph(ROOT)) == []


@pytest.mark.parametrize("layer", ["robot", "plugins", "tasks/reach", "diagnostics", "rl", "cli"])
def test_each_layer_is_a_folder_with_a_docstring_that_says_what_is_in_it(layer: str) -> None:
    init = ROOT / layer / "__init__.py"
    assert init.is_file()
    assert ast.get_docstring(ast.parse(init.read_text())), f"{layer}/__init__.py says nothing of its folder"


def test_the_robot_layer_imports_no_engine_no_env_and_no_plugin() -> None:
    graph = import_graph(ROOT)
    for module, imported in graph.items():
        if module.startswith("armreach_core.robot"):
            above = [m for m in imported if not m.startswith(("armreach_core.robot", "armreach_core.errors"))]
            assert not above, f"{module} reaches up into {above}"


def test_no_module_is_over_the_house_size() -> None:
    big = {
        str(path.relative_to(ROOT.parent)): n
        for folder in [ROOT, *DISTRIBUTIONS]
        for path in folder.rglob("*.py")
        if (n := len(path.read_text().splitlines())) > MAX_MODULE_LINES
    }
    assert big == {}


def test_every_old_import_path_still_works_and_warns() -> None:
    # A fresh interpreter, where no old name is imported yet.
    code = (
        "import warnings, importlib, json, sys, armreach_core\n"
        "moved = json.loads(sys.argv[1])\n"
        "for old, new in moved.items():\n"
        "    with warnings.catch_warnings(record=True) as caught:\n"
        "        warnings.simplefilter('always')\n"
        "        module = importlib.import_module(old)\n"
        "    assert module is importlib.import_module(new), old\n"
        "    assert any(issubclass(w.category, DeprecationWarning) and new in str(w.message) for w in caught), old\n"
    )
    result = subprocess.run(
        [sys.executable, "-c", code, json.dumps(MOVED)], capture_output=True, text=True, timeout=120
    )
    assert result.returncode == 0, result.stderr[-2000:]


def test_the_new_paths_import_without_any_deprecation() -> None:
    code = (
        "import warnings\nwarnings.simplefilter('error', DeprecationWarning)\n"
        "import armreach_core, armreach_core.robot.model, armreach_core.diagnostics.contract, "
        "armreach_core.tasks.reach.env, armreach_core.plugins.lookup\n"
    )
    result = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=120)
    assert result.returncode == 0, result.stderr[-2000:]


def test_the_core_never_imports_a_backend_or_task_distribution_by_name() -> None:
    for path in ROOT.rglob("*.py"):
        tree = ast.parse(path.read_text())
        for node in ast.walk(tree):
            names = [a.name for a in node.names] if isinstance(node, ast.Import) else []
            if isinstance(node, ast.ImportFrom) and node.module:
                names = [node.module]
            for name in names:
                assert not name.startswith(
                    ("armreach_pybullet", "armreach_mujoco", "armreach_grasp", "armreach_obstacles")
                ), (path, name)


def test_plugin_modules_are_cheap_entry_point_strings() -> None:
    """Each shipped plugin names its classes as 'module:attr' (resolved when needed), so
    importing the plugin module imports no engine and no task; each names a module that exists."""
    registry = armreach_core.get_host().registry
    for spec in [*registry.backends.values(), *registry.tasks.values()]:
        assert isinstance(spec.load, str), f"{spec.name}: {spec.load!r}"
        module, _, attr = spec.load.partition(":")
        assert attr, spec.load
        assert importlib.util.find_spec(module) is not None, spec.load  # found without importing the engine
