"""ruff over the tree and mypy over the common, physics and attacker layers, with the rules in pyproject.toml."""

import subprocess
import sys
from pathlib import Path

import pytest

pytestmark = pytest.mark.slow  # ruff and mypy in subprocesses (mypy takes a while)

ROOT = Path(__file__).resolve().parent.parent


def run(*args: str) -> subprocess.CompletedProcess:
    return subprocess.run([sys.executable, "-m", *args], cwd=ROOT, capture_output=True, text=True, timeout=600)


def test_ruff_passes():
    proc = run("ruff", "check", "lenses", "attacks", "benchmark", "tests")
    assert proc.returncode == 0, proc.stdout[-4000:] + proc.stderr[-2000:]


def test_ruff_would_catch_an_unused_import(tmp_path):
    bad = tmp_path / "bad.py"
    bad.write_text("import os\n")
    proc = run("ruff", "check", "--config", str(ROOT / "pyproject.toml"), str(bad))
    assert proc.returncode == 1 and "F401" in proc.stdout


def test_mypy_passes_on_common_lenses_and_attacks():
    proc = run("mypy", "common", "lenses", "attacks")
    assert proc.returncode == 0, proc.stdout[-4000:] + proc.stderr[-2000:]
