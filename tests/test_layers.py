"""The layers hold: common <- lenses (physics) <- attacks <- benchmark, inside benchmark one strict order of its
stage packages (store <- scenes <- results <- codesign <- runner <- studies <- publish <- api <- cli),
inside attacks one strict order of its rooms (ATTACK_ROOMS), no two module files share a basename,
and no module imports itself back.

Reads every .py file of the four packages with `ast` (no import is executed), so an import
hidden inside a function counts as much as one at the top.
"""

import ast
import functools
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parent.parent
PACKAGES = ("common", "lenses", "attacks", "benchmark")
# What each package may import of ours (anything else of ours is a backward arrow).
ALLOWED = {"common": {"common"}, "lenses": {"common", "lenses"}, "attacks": {"common", "lenses", "attacks"},
           "benchmark": {"common", "lenses", "attacks", "benchmark"}}
# benchmark's stages, bottom to top: each may import only itself and those before it. The package
# root (`benchmark/__init__.py`, `__main__.py`) stands above them all.
STAGES = ("store", "scenes", "results", "codesign", "runner", "studies", "publish", "api", "cli")


def module_name(path: Path) -> str:
    parts = list(path.relative_to(ROOT).with_suffix("").parts)
    return ".".join(parts[:-1] if parts[-1] == "__init__" else parts)


def modules() -> dict[str, Path]:
    return {module_name(p): p for pkg in PACKAGES for p in sorted((ROOT / pkg).rglob("*.py"))}


def import_graph() -> dict[str, set[str]]:
    """Module -> our modules it imports (the most specific module each import names), a copy of its own for
    each caller: the tree is parsed once per session."""
    return {name: set(targets) for name, targets in _import_graph().items()}


@functools.cache
def _import_graph() -> dict[str, set[str]]:
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


def stage(module: str) -> str | None:
    """The stage of a benchmark module (its first name below `benchmark`), or None for the package root."""
    parts = module.split(".")
    if parts[0] != "benchmark" or len(parts) < 2 or parts[1] == "__main__":
        return None
    return parts[1]


def stage_violations(graph: dict[str, set[str]]) -> list[str]:
    """Imports from a benchmark stage to a later one in STAGES (or to a folder STAGES does not name)."""
    bad = []
    for name, deps in sorted(graph.items()):
        here = stage(name)
        if here is None:
            continue
        for d in sorted(deps):
            there = stage(d)
            if there is None and d.startswith("benchmark"):
                bad.append(f"{name} -> {d} (the package root)")
            elif there is not None and (here not in STAGES or there not in STAGES
                                        or STAGES.index(there) > STAGES.index(here)):
                bad.append(f"{name} -> {d}")
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


def test_benchmark_stages_in_one_strict_order():
    assert stage_violations(import_graph()) == []


def test_every_entry_of_benchmark_is_a_named_stage():
    entries = {p.stem for p in (ROOT / "benchmark").iterdir() if p.name not in ("__init__.py", "__main__.py",
                                                                               "py.typed", "__pycache__")}
    assert entries == set(STAGES)


def test_stage_check_fails_on_a_planted_backward_import():
    graph = import_graph()
    planted = {**graph, "benchmark.results.schema": graph["benchmark.results.schema"] | {"benchmark.runner.tasks"}}
    assert stage_violations(planted) == ["benchmark.results.schema -> benchmark.runner.tasks"]
    planted = {**graph, "benchmark.store.cache": {"benchmark.publish.report"}, "benchmark.codesign.trainer": {"benchmark"}}
    assert stage_violations(planted) == ["benchmark.codesign.trainer -> benchmark (the package root)",
                                         "benchmark.store.cache -> benchmark.publish.report"]


def test_the_checks_catch_what_they_look_for():
    graph = {"lenses.optics": {"attacks.base"}, "attacks.base": {"benchmark.store.cache"}, "benchmark.a": {"benchmark.b"},
             "benchmark.b": {"benchmark.c"}, "benchmark.c": {"benchmark.a"}}
    assert backward_imports(graph) == ["attacks.base -> benchmark.store.cache", "lenses.optics -> attacks.base"]
    assert cycles(graph) == [["benchmark.a", "benchmark.b", "benchmark.c"]]


@pytest.mark.parametrize("name", ["benchmark.runner.runner", "benchmark.runner.tasks", "attacks.training.restorer_training"])
def test_graph_sees_real_imports(name):
    assert import_graph()[name], f"{name} imports nothing of ours? the ast walk is broken"


def duplicate_basenames(paths: list[Path]) -> dict[str, list[str]]:
    """Basenames of module files (packages' ``__init__`` and ``__main__`` aside) that occur more than once,
    with where: `grep`, a traceback or an editor tab then names one file."""
    seen: dict[str, list[str]] = {}
    for path in paths:
        if path.name not in ("__init__.py", "__main__.py"):
            seen.setdefault(path.stem, []).append(str(path.relative_to(ROOT)))
    return {name: where for name, where in sorted(seen.items()) if len(where) > 1}


def test_no_two_modules_share_a_basename():
    assert duplicate_basenames(list(modules().values())) == {}


def test_the_basename_check_fails_on_a_planted_duplicate():
    planted = list(modules().values()) + [ROOT / "benchmark" / "results" / "charts" / "crops.py"]
    assert duplicate_basenames(planted) == {"crops": ["common/crops.py", "benchmark/results/charts/crops.py"]}


def test_common_is_the_lowest_layer():
    graph = import_graph()
    assert {m for m in graph if m.startswith("common")} >= {"common.plugins", "common.offline", "common.plate_render",
                                                           "common.crops"}
    planted = {**graph, "common.crops": {"lenses.optics"}}
    assert backward_imports(planted) == ["common.crops -> lenses.optics"]


# attacks' rooms, bottom to top: the plugin API, then what attackers share, then the attackers. Each may
# import only itself and the rooms before it (the plate pipeline's stages are a room of their own).
ATTACK_ROOMS = ("base", "registry", "backends", "networks", "readers.plates", "training", "restorers", "readers")


def attack_room(module: str) -> str | None:
    """The room of an attacks module (its first name below `attacks`; readers.plates apart), None for the root."""
    parts = module.split(".")
    if parts[0] != "attacks" or len(parts) < 2:
        return None
    return "readers.plates" if parts[1:3] == ["readers", "plates"] else parts[1]


def room_violations(graph: dict[str, set[str]]) -> list[str]:
    """Imports from an attacks room to a later one in ATTACK_ROOMS (or to a room it does not name)."""
    bad = []
    for name, deps in sorted(graph.items()):
        here = attack_room(name)
        if here is None:
            continue
        for d in sorted(deps):
            there = attack_room(d)
            if there is not None and there != here and (here not in ATTACK_ROOMS or there not in ATTACK_ROOMS
                                                        or ATTACK_ROOMS.index(there) > ATTACK_ROOMS.index(here)):
                bad.append(f"{name} -> {d}")
    return bad


def test_attacks_rooms_in_one_strict_order():
    assert room_violations(import_graph()) == []


def test_every_entry_of_attacks_is_a_named_room():
    entries = {p.stem for p in (ROOT / "attacks").iterdir() if p.name not in ("__init__.py", "py.typed", "__pycache__",
                                                                             "weights")}
    assert entries == {r.split(".")[0] for r in ATTACK_ROOMS}


def test_registered_attackers_live_in_the_attacker_rooms():
    from importlib.metadata import entry_points
    modules = {ep.value.split(":")[0] for ep in entry_points(group="privacy_lens_bench.attacks")
               if ep.value.startswith("attacks.")}
    assert modules and all(attack_room(m) in ("restorers", "readers") for m in modules), sorted(modules)


def test_room_check_fails_on_a_planted_backward_import():
    graph = import_graph()
    planted = {**graph, "attacks.training.shipped_weights": graph["attacks.training.shipped_weights"]
               | {"attacks.restorers.identity"}}
    assert room_violations(planted) == ["attacks.training.shipped_weights -> attacks.restorers.identity"]
