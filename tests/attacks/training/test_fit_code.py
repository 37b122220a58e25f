"""Cached and shipped fits are keyed by the code that made them (attacks.training.fit_code).

The pin: a digest of every source a fit's module imports, transitively, within the project's packages. It
fails when the training code changes, so that the change is judged (raise the version, or renew the pin) and
never silently served from weights the old code made.
"""

from __future__ import annotations

import ast
import hashlib
from pathlib import Path

import pytest

from attacks.training import fit_code
from attacks.training.fit_code import FIT_CODE, versioned_key
from benchmark.store.provenance import source_digest

ROOT = Path(__file__).resolve().parents[3]
PACKAGES = ("attacks", "common", "lenses")
NOT_PINNED = {"attacks/training/fit_code.py"}  # the pins themselves


def module_file(name: str) -> Path | None:
    """The source of a project module (None outside PACKAGES or not a file of the tree)."""
    if name.split(".")[0] not in PACKAGES:
        return None
    base = ROOT.joinpath(*name.split("."))
    for path in (base.with_suffix(".py"), base / "__init__.py"):
        if path.is_file():
            return path
    return None


def imported(path: Path) -> set[str]:
    """Every module `path` imports, at any depth of its code (`from a import b` counts a.b where that is one)."""
    names: set[str] = set()
    for node in ast.walk(ast.parse(path.read_text(encoding="utf-8"))):
        if isinstance(node, ast.Import):
            names.update(alias.name for alias in node.names)
        elif isinstance(node, ast.ImportFrom) and node.module and node.level == 0:
            names.add(node.module)
            names.update(f"{node.module}.{alias.name}" for alias in node.names)
    return names


def closure(module: str) -> list[Path]:
    """The project sources `module` runs: its file, the packages' __init__ on the way, what they import."""
    seen: set[Path] = set()
    todo = [module]
    while todo:
        name = todo.pop()
        parts = name.split(".")
        for i in range(1, len(parts) + 1):  # importing a.b.c runs a/__init__ and a/b/__init__ too
            path = module_file(".".join(parts[:i]))
            if path is None or path in seen or path.relative_to(ROOT).as_posix() in NOT_PINNED:
                continue
            seen.add(path)
            todo.extend(imported(path))
    return sorted(seen)


def closure_digest(module: str) -> str:
    digest = hashlib.sha256()
    for path in closure(module):
        digest.update(path.relative_to(ROOT).as_posix().encode() + b"\0" + source_digest(path.read_bytes()))
    return digest.hexdigest()


@pytest.mark.parametrize("attack", sorted(FIT_CODE))
def test_the_fit_code_is_pinned(attack):
    code = FIT_CODE[attack]
    got = closure_digest(code.module)
    assert got == code.pinned, (
        f"the sources that fit {attack} changed ({len(closure(code.module))} files imported from {code.module}). "
        f"If the change alters what is fitted, raise FIT_CODE[{attack!r}].version in attacks/training/fit_code.py "
        f"(its cached fits are made again; a shipped fit must be shipped again); either way set its pin to {got}")


def test_the_closure_follows_imports_and_a_changed_source_moves_the_digest(tmp_path, monkeypatch):
    files = closure("attacks.readers.learned_reader")
    rel = {p.relative_to(ROOT).as_posix() for p in files}
    # Direct and indirect imports, the package __init__ files, nothing outside the project, not the pins.
    assert {"attacks/readers/learned_reader.py", "attacks/training/plate_reader_training.py",
            "attacks/networks/plate_cnn.py", "common/plate_render.py", "attacks/__init__.py"} <= rel
    assert "attacks/training/fit_code.py" not in rel and all(r.split("/")[0] in PACKAGES for r in rel)
    before = closure_digest("attacks.readers.learned_reader")
    # The injected fault: a copy of the tree whose network differs in one constant.
    for package in PACKAGES:
        for path in (ROOT / package).rglob("*.py"):
            target = tmp_path / path.relative_to(ROOT)
            target.parent.mkdir(parents=True, exist_ok=True)
            target.write_bytes(path.read_bytes())
    cnn = tmp_path / "attacks" / "networks" / "plate_cnn.py"
    cnn.write_text(cnn.read_text(encoding="utf-8") + "\nEXTRA_CONSTANT = 1\n", encoding="utf-8")
    monkeypatch.setitem(globals(), "ROOT", tmp_path)
    assert closure_digest("attacks.readers.learned_reader") != before


def test_version_one_keeps_the_keys_made_before_it(monkeypatch):
    key = {"attack": "learned-reader", "seed": 0}
    assert versioned_key("learned-reader", key) == key
    monkeypatch.setitem(fit_code.FIT_CODE, "learned-reader", fit_code.FitCode("m", 2, "x"))
    assert versioned_key("learned-reader", key) == {**key, "fit_code": 2}
