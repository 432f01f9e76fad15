"""pecli's dependencies point one way: no import cycle between modules, nor between its packages.

Every import counts, also those inside functions and under ``TYPE_CHECKING``: a lazy import hides a cycle from
the interpreter, not from a reader.
"""

from __future__ import annotations

import ast
from collections import defaultdict
from pathlib import Path

import pecli

ROOT = Path(pecli.__file__).parent
PACKAGES = ("pecli", "wrappers")  # the training views sit beside pecli, below its learning code


def _modules() -> dict[str, Path]:
    modules = {}
    for path in (file for package in PACKAGES for file in (ROOT.parent / package).rglob("*.py")):
        parts = path.relative_to(ROOT.parent).with_suffix("").parts
        name = ".".join(parts[:-1] if parts[-1] == "__init__" else parts)
        modules[name] = path
    return modules


def _imports(name: str, path: Path) -> set[str]:
    """Every pecli (or wrappers) module ``name`` imports (a name imported from a package counts as its submodule
    if one)."""
    found = set()
    package = name.split(".") if path.name == "__init__.py" else name.split(".")[:-1]
    for node in ast.walk(ast.parse(path.read_text(), str(path))):
        if isinstance(node, ast.Import):
            found.update(alias.name for alias in node.names)
        elif isinstance(node, ast.ImportFrom):
            base = (
                ".".join(package[: len(package) - node.level + 1] + [node.module or ""]).strip(".")
                if node.level
                else node.module or ""
            )
            found.add(base)
            found.update(f"{base}.{alias.name}" for alias in node.names)
    return {imported for imported in found if imported.partition(".")[0] in PACKAGES}


def _graph(unit) -> dict[str, set[str]]:
    modules = _modules()
    graph: dict[str, set[str]] = defaultdict(set)
    for name, path in modules.items():
        for imported in _imports(name, path):
            while imported not in modules:
                imported = imported.rpartition(".")[0]
            source, target = unit(name), unit(imported)
            if imported not in PACKAGES and source != target and not source.startswith(target + "."):
                graph[source].add(target)
    return graph


def _cycles(graph: dict[str, set[str]]) -> list[list[str]]:
    """The strongly connected components of more than one node (Tarjan)."""
    index: dict[str, int] = {}
    low: dict[str, int] = {}
    stack: list[str] = []
    components = []

    def visit(node: str) -> None:
        index[node] = low[node] = len(index)
        stack.append(node)
        for successor in graph.get(node, ()):
            if successor not in index:
                visit(successor)
                low[node] = min(low[node], low[successor])
            elif successor in stack:
                low[node] = min(low[node], index[successor])
        if low[node] == index[node]:
            component = []
            while True:
                member = stack.pop()
                component.append(member)
                if member == node:
                    break
            if len(component) > 1:
                components.append(sorted(component))

    for node in list(graph):
        if node not in index:
            visit(node)
    return components


def test_no_module_imports_itself_back():
    assert _cycles(_graph(lambda name: name)) == []


def test_packages_are_layered():
    """``pecli.game`` ← ``pecli.belief`` ← ``pecli.models`` ← ``pecli.policies`` ← ``wrappers`` ← ``pecli.rl`` ← ...
    never back."""
    assert _cycles(_graph(lambda name: ".".join(name.split(".")[:2]))) == []


def test_the_check_sees_a_cycle():
    assert _cycles({"a": {"b"}, "b": {"c"}, "c": {"a"}, "d": {"a"}}) == [["a", "b", "c"]]


def test_the_lower_layers_import_nothing_above_them():
    graph = _graph(lambda name: ".".join(name.split(".")[:2]))
    assert not graph["pecli.game"] & {"pecli.policies", "pecli.models", "pecli.rl", "pecli.match"}
    assert "pecli.rl" not in graph["pecli.policies"] and "pecli.rl" not in graph["pecli.models"]
    below = graph["pecli.models"] | graph["pecli.policies"] | graph["pecli.game"] | graph["pecli.belief"]
    assert not [name for name in below if name.partition(".")[0] == "wrappers"]


def test_records_load_no_network() -> None:
    """A run's records are read (and refused) without loading torch or Stable-Baselines3."""
    import subprocess
    import sys

    code = (
        "import sys, pecli.records, pecli.rl.state, pecli.experiment.compare; "
        "assert not {'torch', 'stable_baselines3'} & set(sys.modules), sorted(sys.modules)"
    )
    subprocess.run([sys.executable, "-c", code], check=True)
