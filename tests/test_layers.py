"""The layers hold: lenses (physics) <- attacks <- benchmark, and no module imports itself back.

Reads every .py file of the three packages with `ast` (no import is executed), so an import
hidden inside a function counts as much as one at the top.
"""

import ast
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parent.parent
PACKAGES = ("lenses", "attacks", "benchmark")
# What each package may import of ours (anything else of ours is a backward arrow).
ALLOWED = {"lenses": {"lenses"}, "attacks": {"lenses", "attacks"}, "benchmark": {"lenses", "attacks", "benchmark"}}


def module_name(path: Path) -> str:
    parts = list(path.relative_to(ROOT).with_suffix("").parts)
    return ".".join(parts[:-1] if parts[-1] == "__init__" else parts)


def modules() -> dict[str, Path]:
    return {module_name(p): p for pkg in PACKAGES for p in sorted((ROOT / pkg).rglob("*.py"))}


def import_graph() -> dict[str, set[str]]:
    """Module -> our modules it imports (the most specific module each import names)."""
    known = modules()
    graph = {}
    for name, path in known.items():
        direct = set()
        for node in ast.walk(ast.parse(path.read_text(), filename=str(path))):
            if isinstance(node, ast.Import):
                direct |= {_resolve(a.name, known) for a in node.names}
            elif isinstance(node, ast.ImportFrom):
                base = _absolute(name, path, node)
                direct |= {_resolve(f"{base}.{a.name}", known) for a in node.names}
        graph[name] = {d for d in direct if d and d != name}
    return graph


def _absolute(name: str, path: Path, node: ast.ImportFrom) -> str:
    if not node.level:
        return node.module or ""
    package = name if path.name == "__init__.py" else name.rpartition(".")[0]
    for _ in range(node.level - 1):
        package = package.rpartition(".")[0]
    return f"{package}.{node.module}" if node.module else package


def _resolve(target: str, known: dict[str, Path]) -> str:
    """The most specific module of ours that `target` (a module or module.attribute) names, or ''."""
    while target and target not in known:
        target = target.rpartition(".")[0]
    return target


def backward_imports(graph: dict[str, set[str]]) -> list[str]:
    bad = []
    for name, deps in sorted(graph.items()):
        top = name.split(".")[0]
        bad += [f"{name} -> {d}" for d in sorted(deps) if d.split(".")[0] not in ALLOWED[top]]
    return bad


def cycles(graph: dict[str, set[str]]) -> list[list[str]]:
    """Strongly connected components of more than one module (Tarjan)."""
    index: dict[str, int] = {}
    low: dict[str, int] = {}
    stack: list[str] = []
    on_stack: set[str] = set()
    found: list[list[str]] = []

    def visit(v: str) -> None:
        index[v] = low[v] = len(index)
        stack.append(v)
        on_stack.add(v)
        for w in sorted(graph.get(v, ())):
            if w not in index:
                visit(w)
                low[v] = min(low[v], low[w])
            elif w in on_stack:
                low[v] = min(low[v], index[w])
        if low[v] == index[v]:
            component = []
            while True:
                w = stack.pop()
                on_stack.discard(w)
                component.append(w)
                if w == v:
                    break
            if len(component) > 1:
                found.append(sorted(component))

    for v in sorted(graph):
        if v not in index:
            visit(v)
    return found


def test_no_backward_import():
    assert backward_imports(import_graph()) == []


def test_no_import_cycle():
    assert cycles(import_graph()) == []


def test_the_checks_catch_what_they_look_for():
    graph = {"lenses.optics": {"attacks.base"}, "attacks.base": {"benchmark.cache"}, "benchmark.a": {"benchmark.b"},
             "benchmark.b": {"benchmark.c"}, "benchmark.c": {"benchmark.a"}}
    assert backward_imports(graph) == ["attacks.base -> benchmark.cache", "lenses.optics -> attacks.base"]
    assert cycles(graph) == [["benchmark.a", "benchmark.b", "benchmark.c"]]


@pytest.mark.parametrize("name", ["benchmark.runner", "benchmark.tasks", "attacks.restorer_training"])
def test_graph_sees_real_imports(name):
    assert import_graph()[name], f"{name} imports nothing of ours? the ast walk is broken"
