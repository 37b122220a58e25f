"""Source, tests and docs say what is, not how it came to be: no issue number and no commit hash (which
mean nothing to a reader; the history is in git and docs/history.md), and every file or module they name
exists. Each check is also run on planted text, so that it cannot pass by matching nothing."""

from __future__ import annotations

import ast
import io
import re
import tokenize
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
PACKAGES = ("common", "lenses", "attacks", "benchmark", "tests")

# "issue" or "issues" and a number, or "#" and a number; not a colour ("#" after a quote or a colon, or a
# CSS border's style, as in page.py) nor a unit name's index ("s/a#" and a digit: after a word character
# or an f-string's field).
ISSUE = re.compile(r"\bissues? \d+|(?<![\w\"':#&}])(?<!solid )(?<!dashed )(?<!dotted )#\d+\b", re.IGNORECASE)
# A commit hash: a word of 7-40 lowercase hex characters with at least one digit and one letter a-f.
HASH = re.compile(r"\b(?=[0-9a-f]*[a-f])(?=[0-9a-f]*[0-9])[0-9a-f]{7,40}\b")
DIGEST_LABEL = re.compile(r"sha-?256[ :=]*$", re.IGNORECASE)  # "SHA-256 ff1b26f78e488e8d": a data digest
FAKE_HASHES = {"0123456789abcdef"}  # the ascending hex digits: a test's fake config hash, no commit's


def scanned_files() -> list[Path]:
    """Every .py of the packages and the tests, every .md of docs/, the README and the leaderboard's."""
    files = [p for package in PACKAGES for p in sorted((ROOT / package).rglob("*.py"))]
    return files + sorted((ROOT / "docs").glob("*.md")) + [ROOT / "README.md", ROOT / "leaderboard" / "README.md"]


def history_pointers(text: str) -> list[str]:
    """The issue numbers and commit hashes in `text`, each as "line N: match"."""
    found = []
    for n, line in enumerate(text.splitlines(), 1):
        found += [f"line {n}: {m.group(0)}" for m in ISSUE.finditer(line)]
        found += [f"line {n}: {m.group(0)}" for m in HASH.finditer(line)
                  if m.group(0) not in FAKE_HASHES and not DIGEST_LABEL.search(line[:m.start()])]
    return found


def test_no_issue_number_or_commit_hash_in_source_tests_or_docs():
    files = scanned_files()
    assert len(files) > 300 and Path(__file__) in files and ROOT / "docs" / "history.md" in files
    found = [f"{path.relative_to(ROOT)} {hit}" for path in files for hit in history_pointers(path.read_text())]
    assert found == []


def test_the_history_check_catches_what_it_looks_for():
    commit = "98" + "7a3a3"  # built here, so that this file holds none itself
    planted = [f"fixed in issue {47}", f"Issues {13} and 14", f"see (#{37})", f"ISSUE {38}: a sentence",
               f"at {commit}, then", f"({commit})", commit + "e9c8ab" + "5", "1" * 39 + "a"]
    for text in planted:
        assert history_pointers(text), text
    innocent = ['color="#' + '1f77b4"', "color:#" + "222;", "1px solid #" + "888;", 'names = ["s/a#' + '0", "s/a#' + '1"]', 'f"{i}#' + '0"', "deadbeefcafe",
                "1234567", "config_" + commit, commit.upper(), "SHA-256 " + commit + "f" * 9, "sha256 " + "a1" * 32,
                '"config_hash": "0123456789abcdef"', commit + "0" * 34, commit[:6], "issue tracker", "issues: none"]
    for text in innocent:
        assert not history_pointers(text), text


# Where a path or a module of ours is named: `attacks/readers/lpdr.py`, ``benchmark.runner.tasks.execute``.
PATH = re.compile(r"(?<![\w./-])((?:common|lenses|attacks|benchmark|tests|docs|leaderboard)/[\w./-]*[\w/])(?:::(\w+))?")
MODULE = re.compile(r"(?<![\w./-])((?:common|lenses|attacks|benchmark|tests)(?:\.[A-Za-z_]\w*)+)")
PATTERN_NEXT = set("<*{")  # `attacks/weights/nafnet-generic-<profile>`, `...-s0.*`: a pattern, not one file
NOT_NAMES = {"pedantic", "extra_info", "stats"}  # pytest-benchmark's `benchmark` fixture, not our package


def defined(module: Path, name: str) -> bool:
    """Whether `module` defines, assigns, imports or (a package) exports `name` at any level."""
    for node in ast.walk(ast.parse(module.read_text())):
        if isinstance(node, (ast.FunctionDef, ast.AsyncFunctionDef, ast.ClassDef)) and node.name == name:
            return True
        if isinstance(node, (ast.Import, ast.ImportFrom)) and any(
                (a.asname or a.name.split(".")[-1]) == name for a in node.names):
            return True
        if isinstance(node, (ast.Name, ast.Attribute)) and isinstance(node.ctx, ast.Store) and name in (
                getattr(node, "id", None), getattr(node, "attr", None)):
            return True
        if module.name == "__init__.py" and isinstance(node, ast.Constant) and node.value == name:
            return True  # listed in __all__ or a lazy export table
    return False


def module_exists(dotted: str) -> bool:
    """Whether `dotted` is a module of ours, or a name the longest module prefix of it defines."""
    parts = dotted.split(".")
    for i in range(len(parts), 0, -1):
        base = ROOT.joinpath(*parts[:i])
        module = base.with_suffix(".py") if base.with_suffix(".py").is_file() else base / "__init__.py"
        if module.is_file() or (i == 1 and base.is_dir()):
            rest = parts[i:]
            return not rest or rest[0].startswith("__") or rest[0] in NOT_NAMES or (
                module.is_file() and defined(module, rest[0]))
    return False


def prose(path: Path) -> str:
    """What `path` says in words: a test module's comments and docstrings (its code strings hold made-up
    paths on purpose), every other file whole."""
    text = path.read_text()
    return comments_and_docstrings(text) if path.suffix == ".py" and ROOT / "tests" in path.parents else text


def comments_and_docstrings(text: str) -> str:
    """The comments and docstrings of the Python source `text`, each on its own line's place."""
    lines = [""] * len(text.splitlines())
    for token in tokenize.generate_tokens(io.StringIO(text).readline):
        if token.type == tokenize.COMMENT:
            lines[token.start[0] - 1] += token.string
    for node in ast.walk(ast.parse(text)):
        body = getattr(node, "body", None)
        if isinstance(body, list) and body and isinstance(body[0], ast.Expr) and isinstance(
                getattr(body[0], "value", None), ast.Constant) and isinstance(body[0].value.value, str):
            for k, line in enumerate(body[0].value.value.splitlines()):
                lines[body[0].lineno - 1 + k] += " " + line
    return "\n".join(lines)


def stale_pointers(text: str, where: Path) -> list[str]:
    """The paths and modules of ours that `text` (of the file `where`) names and that do not exist."""
    found = []
    for n, line in enumerate(text.splitlines(), 1):
        for m in PATH.finditer(line):
            path, test = m.group(1).rstrip("."), m.group(2)
            if PATTERN_NEXT & set(line[m.end(1):m.end(1) + 2]):
                continue
            if not ((ROOT / path).exists() or (where.parent / path).exists()):
                found.append(f"line {n}: {path}")
            elif test and (ROOT / path).is_file() and not defined(ROOT / path, test):
                found.append(f"line {n}: {m.group(0)}")
        found += [f"line {n}: {m.group(1)}" for m in MODULE.finditer(line)
                  if not m.group(1).endswith((".py", ".md", ".json", ".toml")) and not module_exists(m.group(1))]
    return found


@pytest.mark.slow
def test_every_file_and_module_named_in_source_tests_and_docs_exists():
    found = [f"{path.relative_to(ROOT)} {hit}" for path in scanned_files() for hit in stale_pointers(prose(path), path)]
    assert found == []


def test_the_pointer_check_catches_what_it_looks_for():
    here = ROOT / "tests" / "test_history.py"
    stale = ["see DESIGN in tests/attacks/test_gone.py", "(benchmark/plates.py)", "``attacks.readers.gone``",
             "benchmark.runner.runner.no_such_function", "tests/test_history.py::test_no_such_test"]
    for text in stale:
        assert stale_pointers(text, here), text
    fine = ["attacks/readers/lpdr.py", "``attacks.base.Reader``", "benchmark.run", "attacks/weights/nafnet-generic-<p>",
            "tests/test_history.py::test_the_pointer_check_catches_what_it_looks_for", "docs/history.md",
            "benchmark.pedantic(run)", "lenses.__file__"]
    for text in fine:
        assert not stale_pointers(text, here), text
    planted = 'x = "benchmark/nowhere.py"  # a made-up path in code\n# but named in words: benchmark/gone.py\n'
    assert stale_pointers(comments_and_docstrings(planted), here) == ["line 2: benchmark/gone.py"]
