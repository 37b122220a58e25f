"""The fast tier (`python -m pytest -m "not slow"`) leaves out every test that starts a subprocess, every
regression re-check and the browser test; the speed benchmarks stay out of any run without `--benchmark-only`.

Reads the test files with `ast` (nothing is run or imported). A test starts a subprocess when its body, a
function of its file it uses, or a fixture it asks for (of its file or a conftest.py above it) calls
`subprocess.*`, `os.system`, `os.popen`, `os.spawn*`, `os.exec*` or `asyncio.create_subprocess_*`, or
spells a `-m benchmark...` command line. `multiprocessing` workers (forks of the test process itself) and
which tests take more than a few seconds are judged by a run's `--durations=0`, not here.
"""

from __future__ import annotations

import ast
import functools
import tomllib
from pathlib import Path

import pytest

TESTS = Path(__file__).resolve().parent
ROOT = TESTS.parent
BROWSER_MODULES = ("selenium", "playwright", "pyppeteer")
_SUBPROCESS_SPAWNERS = {"run", "Popen", "call", "check_call", "check_output", "getoutput", "getstatusoutput"}
_OS_SPAWNERS = ("system", "popen", "spawn", "exec", "posix_spawn", "fork")


class Module:
    """One test file: its functions by name, its fixtures, its module-level marks and its imports."""

    def __init__(self, source: str, conftest_fixtures: dict[str, ast.FunctionDef] | None = None):
        self.tree = ast.parse(source)
        self.functions = {n.name: n for n in self.tree.body if isinstance(n, (ast.FunctionDef, ast.AsyncFunctionDef))}
        self.fixtures = dict(conftest_fixtures or {})
        self.fixtures.update({name: f for name, f in self.functions.items() if _is_fixture(f)})
        self.slow = any(_marks_slow(n.value) for n in self.tree.body if _assigns(n, "pytestmark"))
        self.subprocess_names, self.os_names = _imported_names(self.tree)
        self._spawning: set[str] | None = None
        self._memo: dict[tuple[str, int], object] = {}  # (what, id of the function) -> answer: each walked once

    def tests(self):
        """(test id, function, slow) for every test function and test method."""
        for node in self.tree.body:
            if isinstance(node, (ast.FunctionDef, ast.AsyncFunctionDef)) and node.name.startswith("test"):
                yield node.name, node, self.slow or _decorated_slow(node)
            elif isinstance(node, ast.ClassDef) and node.name.startswith("Test"):
                class_slow = self.slow or _decorated_slow(node) or any(
                    _marks_slow(n.value) for n in node.body if _assigns(n, "pytestmark"))
                for item in node.body:
                    if isinstance(item, (ast.FunctionDef, ast.AsyncFunctionDef)) and item.name.startswith("test"):
                        yield f"{node.name}::{item.name}", item, class_slow or _decorated_slow(item)

    def spawns(self, function: ast.AST) -> bool:
        return bool(self._uses(function) & self.spawning()) or self._spawns_directly(function) or any(
            name in self.spawning() for name in self._autouse())

    def spawning(self) -> set[str]:
        """Names of this file's functions and fixtures that start a subprocess, themselves or through another."""
        if self._spawning is None:
            known = {**self.fixtures, **self.functions}
            spawning = {name for name, f in known.items() if self._spawns_directly(f)}
            grew = True
            while grew:
                new = {name for name, f in known.items() if name not in spawning and self._uses(f) & spawning}
                spawning |= new
                grew = bool(new)
            self._spawning = spawning
        return self._spawning

    def _autouse(self) -> list[str]:
        return [name for name, f in self.fixtures.items() if _is_fixture(f, autouse=True)]

    def _uses(self, function: ast.AST) -> set[str]:
        """Names the function refers to, the fixtures it asks for and those it names in usefixtures."""
        key = ("uses", id(function))
        if key not in self._memo:
            self._memo[key] = self._names_used(function)
        return self._memo[key]  # type: ignore[return-value]

    def _names_used(self, function: ast.AST) -> set[str]:
        names = {n.id for n in ast.walk(function) if isinstance(n, ast.Name)}
        if isinstance(function, (ast.FunctionDef, ast.AsyncFunctionDef)):
            args = function.args
            names |= {a.arg for a in (*args.posonlyargs, *args.args, *args.kwonlyargs)}
            for decorator in function.decorator_list:
                if isinstance(decorator, ast.Call) and _dotted(decorator.func).endswith("mark.usefixtures"):
                    names |= {a.value for a in decorator.args if isinstance(a, ast.Constant)}
        return names - {function.name} if isinstance(function, (ast.FunctionDef, ast.AsyncFunctionDef)) else names

    def _spawns_directly(self, function: ast.AST) -> bool:
        key = ("spawns", id(function))
        if key not in self._memo:
            self._memo[key] = self._calls_a_spawner(function)
        return self._memo[key]  # type: ignore[return-value]

    def _calls_a_spawner(self, function: ast.AST) -> bool:
        for node in ast.walk(function):
            if isinstance(node, ast.Call):
                name = _dotted(node.func)
                head, _, attribute = name.rpartition(".")
                if (head == "subprocess" and attribute in _SUBPROCESS_SPAWNERS) or name in self.subprocess_names:
                    return True
                if (head == "os" and attribute.startswith(_OS_SPAWNERS)) or name.startswith(self.os_names):
                    return True
                if name.startswith("asyncio.create_subprocess"):
                    return True
            elif isinstance(node, (ast.List, ast.Tuple)):
                words = [e.value for e in node.elts if isinstance(e, ast.Constant) and isinstance(e.value, str)]
                if any(a == "-m" and b.split(".")[0] == "benchmark" for a, b in zip(words, words[1:])):
                    return True
        return False

    def imports_browser(self) -> bool:
        for node in ast.walk(self.tree):
            if isinstance(node, ast.Import) and any(a.name.split(".")[0] in BROWSER_MODULES for a in node.names):
                return True
            if isinstance(node, ast.ImportFrom) and (node.module or "").split(".")[0] in BROWSER_MODULES:
                return True
            if isinstance(node, ast.Call) and _dotted(node.func).endswith("importorskip") and node.args and \
                    isinstance(node.args[0], ast.Constant) and str(node.args[0].value).split(".")[0] in BROWSER_MODULES:
                return True
        return False


def _dotted(node: ast.AST) -> str:
    if isinstance(node, ast.Name):
        return node.id
    if isinstance(node, ast.Attribute):
        return f"{_dotted(node.value)}.{node.attr}"
    return ""


def _assigns(node: ast.AST, name: str) -> bool:
    return isinstance(node, ast.Assign) and any(isinstance(t, ast.Name) and t.id == name for t in node.targets)


def _marks_slow(value: ast.AST) -> bool:
    """`pytest.mark.slow`, alone or in a list or tuple of marks."""
    if isinstance(value, (ast.List, ast.Tuple)):
        return any(_marks_slow(e) for e in value.elts)
    return _dotted(value).endswith("mark.slow")


def _decorated_slow(node: ast.FunctionDef | ast.AsyncFunctionDef | ast.ClassDef) -> bool:
    return any(_marks_slow(d) for d in node.decorator_list)


def _is_fixture(function: ast.AST, autouse: bool = False) -> bool:
    for decorator in getattr(function, "decorator_list", ()):
        name = _dotted(decorator.func if isinstance(decorator, ast.Call) else decorator)
        if name.endswith("fixture"):
            if not autouse:
                return True
            return isinstance(decorator, ast.Call) and any(
                k.arg == "autouse" and isinstance(k.value, ast.Constant) and k.value.value for k in decorator.keywords)
    return False


def _imported_names(tree: ast.Module) -> tuple[set[str], tuple[str, ...]]:
    """Names bound by `from subprocess import run, ...` and `from os import system, ...` (called bare)."""
    from_subprocess, from_os = set(), []
    for node in ast.walk(tree):
        if isinstance(node, ast.ImportFrom) and node.module == "subprocess":
            from_subprocess |= {a.asname or a.name for a in node.names if a.name in _SUBPROCESS_SPAWNERS}
        elif isinstance(node, ast.ImportFrom) and node.module == "os":
            from_os += [a.asname or a.name for a in node.names if a.name.startswith(_OS_SPAWNERS)]
    return from_subprocess, tuple(from_os)


def _conftest_fixtures(path: Path) -> dict[str, ast.FunctionDef]:
    """Fixtures of the conftest.py files from tests/ down to the file's folder (nearer ones win)."""
    fixtures: dict[str, ast.FunctionDef] = {}
    parts = path.parent.relative_to(TESTS).parts
    for depth in range(len(parts) + 1):
        fixtures.update(_fixtures_of_conftest(TESTS.joinpath(*parts[:depth]) / "conftest.py"))
    return fixtures


@functools.cache
def _fixtures_of_conftest(conftest: Path) -> dict[str, ast.FunctionDef]:
    if not conftest.is_file():
        return {}
    return {n.name: n for n in ast.parse(conftest.read_text()).body
            if isinstance(n, (ast.FunctionDef, ast.AsyncFunctionDef)) and _is_fixture(n)}


def _test_files() -> list[Path]:
    return sorted(p for p in TESTS.rglob("test_*.py") if p.is_file())


@functools.cache
def _module(path: Path) -> Module:
    return Module(path.read_text(), _conftest_fixtures(path))


def unmarked_spawning_tests(module: Module) -> list[str]:
    return [name for name, function, slow in module.tests() if not slow and module.spawns(function)]


def test_every_test_that_starts_a_subprocess_is_slow():
    unmarked = [f"{path.relative_to(ROOT)}::{name}" for path in _test_files()
                for name in unmarked_spawning_tests(_module(path))]
    assert not unmarked, "start a subprocess but lack @pytest.mark.slow:\n" + "\n".join(unmarked)


def test_every_regression_and_browser_test_is_slow():
    regression = [p for p in _test_files() if p.is_relative_to(TESTS / "regression")]
    browser = [p for p in _test_files() if _module(p).imports_browser()]
    assert regression and browser, "no regression or browser test found: has tests/ moved?"
    unmarked = [f"{path.relative_to(ROOT)}::{name}" for path in {*regression, *browser}
                for name, _, slow in _module(path).tests() if not slow]
    assert not unmarked, "regression or browser tests outside the slow tier:\n" + "\n".join(sorted(unmarked))


def test_speed_benchmarks_run_only_when_asked():
    """`--benchmark-skip` in addopts skips every test that takes the `benchmark` fixture, in the fast tier too;
    a file under tests/speed holds at least one of them (else it is no speed benchmark and belongs elsewhere)."""
    options = tomllib.loads((ROOT / "pyproject.toml").read_text())["tool"]["pytest"]["ini_options"]
    assert "--benchmark-skip" in options["addopts"].split()
    assert any(m.startswith("slow:") for m in options["markers"])
    speed = [p for p in _test_files() if p.is_relative_to(TESTS / "speed")]
    assert speed
    for path in speed:
        benchmarks = [name for name, function, _ in _module(path).tests()
                      if "benchmark" in {a.arg for a in function.args.args}]
        assert benchmarks, f"{path.relative_to(ROOT)} has no test taking the benchmark fixture"


PLANTED = '''
import subprocess
import sys
import pytest

def _cli(*args):
    return subprocess.run([sys.executable, "-m", "benchmark", *args], capture_output=True)

@pytest.fixture(scope="module")
def smoke_run():
    return _cli("run", "--profile", "smoke")

def test_pure():
    assert 1 + 1 == 2

def test_help():
    assert _cli("--help").returncode == 0

def test_uses_the_run(smoke_run):
    assert smoke_run.returncode == 0

def test_spelled_out():
    import os
    os.system("python -m benchmark list")

@pytest.mark.slow
def test_marked():
    subprocess.run(["true"])
'''


def test_an_unmarked_subprocess_test_is_caught():
    assert unmarked_spawning_tests(Module(PLANTED)) == ["test_help", "test_uses_the_run", "test_spelled_out"]
    marked = Module(PLANTED.replace("import pytest\n", "import pytest\npytestmark = [pytest.mark.slow]\n", 1))
    assert unmarked_spawning_tests(marked) == []


@pytest.mark.parametrize("call", ["from subprocess import run as go\n    go(['true'])",
                                  "from os import system\n    system('true')",
                                  "cmd = ('python', '-m', 'benchmark.studies.x')\n    launch(cmd)"])
def test_other_spellings_are_caught(call):
    assert unmarked_spawning_tests(Module(f"def test_x():\n    {call}\n")) == ["test_x"]


def test_a_monkeypatched_subprocess_is_no_subprocess():
    source = "import subprocess\ndef test_x(monkeypatch):\n    monkeypatch.setattr(subprocess, 'run', print)\n"
    assert unmarked_spawning_tests(Module(source)) == []


def test_a_spawning_autouse_fixture_marks_every_test_of_its_file():
    source = ("import subprocess, pytest\n@pytest.fixture(autouse=True)\ndef warm():\n    subprocess.run(['true'])\n"
              "def test_x():\n    pass\n")
    assert unmarked_spawning_tests(Module(source)) == ["test_x"]
