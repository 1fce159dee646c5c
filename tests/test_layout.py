"""The code's shape (DESIGN section 7): packages by layer, small modules, no import cycles, a
light top-level import. Checked on the source itself, so a regression fails the suite."""

from __future__ import annotations

import ast
import subprocess
import sys
from pathlib import Path

import pytest

SRC = Path(__file__).resolve().parents[1] / "src"
PACKAGE = SRC / "wristtrack"
MAX_LINES = 500


def _modules() -> dict[str, Path]:
    out = {}
    for path in sorted(PACKAGE.rglob("*.py")):
        parts = path.relative_to(SRC).with_suffix("").parts
        if parts[-1] == "__init__":
            parts = parts[:-1]
        out[".".join(parts)] = path
    return out


def _imports(name: str, path: Path, modules: dict[str, Path]) -> set[str]:
    """Every wristtrack module ``name`` imports, at module level or inside functions."""
    package = name if path.name == "__init__.py" else name.rpartition(".")[0]
    found: set[str] = set()
    for node in ast.walk(ast.parse(path.read_text(), str(path))):
        if isinstance(node, ast.Import):
            targets = [a.name for a in node.names]
        elif isinstance(node, ast.ImportFrom):
            base = node.module or ""
            if node.level:
                anchor = package.split(".")
                anchor = anchor[: len(anchor) - (node.level - 1)]
                base = ".".join([*anchor, base] if base else anchor)
            # "from pkg import mod" imports the module pkg.mod when there is one
            targets = [f"{base}.{a.name}" if f"{base}.{a.name}" in modules else base
                       for a in node.names]
        else:
            continue
        for target in targets:
            # importing a.b.c runs a/__init__ and a/b/__init__ too
            parts = target.split(".")
            for i in range(1, len(parts) + 1):
                mod = ".".join(parts[:i])
                if mod in modules and mod != name and not name.startswith(mod + "."):
                    found.add(mod)
    return found


def _cycles(graph: dict[str, set[str]]) -> list[list[str]]:
    """Strongly connected components with more than one module (Tarjan)."""
    index: dict[str, int] = {}
    low: dict[str, int] = {}
    stack: list[str] = []
    on: set[str] = set()
    out: list[list[str]] = []

    def visit(v: str) -> None:
        index[v] = low[v] = len(index)
        stack.append(v)
        on.add(v)
        for w in graph[v]:
            if w not in index:
                visit(w)
                low[v] = min(low[v], low[w])
            elif w in on:
                low[v] = min(low[v], index[w])
        if low[v] == index[v]:
            comp = []
            while True:
                w = stack.pop()
                on.discard(w)
                comp.append(w)
                if w == v:
                    break
            if len(comp) > 1:
                out.append(sorted(comp))

    for v in graph:
        if v not in index:
            visit(v)
    return out


def test_no_import_cycle_counting_imports_inside_functions():
    modules = _modules()
    graph = {name: _imports(name, path, modules) for name, path in modules.items()}
    assert _cycles(graph) == []


def test_the_cycle_finder_finds_a_cycle():
    # the checker itself: a two-module cycle and a three-module one are found, a chain is not
    graph = {"a": {"b"}, "b": {"a"}, "c": {"d"}, "d": {"e"}, "e": {"c"}, "f": {"a"}}
    assert sorted(_cycles(graph)) == [["a", "b"], ["c", "d", "e"]]
    assert _cycles({"a": {"b"}, "b": set()}) == []


def test_no_module_over_500_lines():
    long = {name: n for name, path in _modules().items()
            if (n := len(path.read_text().splitlines())) > MAX_LINES}
    assert long == {}


def test_benchmarks_live_outside_the_package():
    assert [p for p in PACKAGE.rglob("bench*")] == []


def test_packages_by_layer():
    layers = {"detect", "filter", "tracking", "io", "analysis", "report", "pipeline", "sim"}
    assert layers <= {p.name for p in PACKAGE.iterdir() if (p / "__init__.py").exists()}


def test_filter_package_has_no_wrist_knowledge():
    # the generic estimation layer imports nothing of the wrist tracker built on it
    modules = _modules()
    for name, path in modules.items():
        if name.startswith("wristtrack.filter"):
            deps = _imports(name, path, modules)
            assert all(d.startswith(("wristtrack.filter", "wristtrack.geometry",
                                     "wristtrack.errors")) for d in deps), (name, deps)


@pytest.mark.parametrize("heavy", ["matplotlib", "numba", "cv2", "scipy.stats"])
def test_importing_wristtrack_stays_light(heavy):
    code = ("import sys, wristtrack; wristtrack.__version__; "
            f"print({heavy!r} in sys.modules)")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True)
    assert out.stdout.strip() == "False"


def test_every_public_name_resolves_to_what_its_module_defines():
    import importlib

    import wristtrack

    for name, module in wristtrack._API.items():
        assert getattr(wristtrack, name) is getattr(importlib.import_module(module), name)
    assert set(wristtrack._API) <= set(dir(wristtrack))
    with pytest.raises(AttributeError):
        wristtrack.no_such_name  # noqa: B018
