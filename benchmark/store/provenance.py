"""Provenance stamped on every result row: where a number came from."""

from __future__ import annotations

import ast
import datetime as _dt
import functools
import hashlib
import json
import os
import platform
import subprocess
from importlib.metadata import PackageNotFoundError, version
from pathlib import Path

import torch

_PACKAGES = ("torch", "torchvision", "numpy", "scipy", "scikit-image", "opencv-python-headless",
             "transformers", "easyocr", "onnxruntime", "privacy-lens-bench")


@functools.lru_cache(maxsize=1)
def git_commit() -> str:
    """HEAD commit of the source tree (with '-dirty' when it has uncommitted changes), or 'unknown'.

    Read once per process: the code a process runs is what it imported when it started, so a
    commit made while a long run is going must not be stamped on the rest of its rows.
    """
    here = Path(__file__).resolve().parent
    try:
        commit = subprocess.run(["git", "rev-parse", "HEAD"], cwd=here, capture_output=True, text=True,
                                timeout=5, check=True).stdout.strip()
        dirty = subprocess.run(["git", "status", "--porcelain", "--untracked-files=no"], cwd=here,
                               capture_output=True, text=True, timeout=5).stdout.strip()
    except (OSError, subprocess.SubprocessError):
        return "unknown"
    return commit + ("-dirty" if dirty else "")


# What a run's task results do not depend on: the commands that publish and study them, the CLI
# that builds the run's configuration (itself part of every run's key) and the chart drawing.
# What shapes no task result: publishing, studies, charts, the CLI's words, and the measured-cost table a dry
# run quotes (copied from docs/costs.md whenever a run is measured, which must not invalidate that run's cache).
CODE_VERSION_EXCLUDES = ("benchmark/publish/", "benchmark/studies/", "benchmark/results/charts/", "benchmark/cli.py",
                         "benchmark/store/measured_costs.json")


@functools.lru_cache(maxsize=1)
def code_version() -> str:
    """SHA-256 (16 hex digits) over the files of the packages ``lenses``, ``attacks`` and ``benchmark``
    (sources, shipped weights and tables; not CODE_VERSION_EXCLUDES, ``__pycache__`` or ``*.md``) and
    the versions of the packages that shape the numbers. A Python source counts by what it does
    (``source_digest``: its syntax tree without docstrings), so editing a comment, a docstring or the
    layout leaves every cached task result valid.

    Two processes with the same code version compute the same task results, whatever commit they
    were started from: a long job (``publish``) interrupted at one commit resumes at a later one
    that changed only docs, tests or the excluded modules. Read once per process, like git_commit.
    """
    from benchmark.store.cache import cache_root

    return code_digest(Path(__file__).resolve().parents[2], memo=cache_root() / "code-digests.json")


def code_digest(root: Path, memo: Path | None = None, packages: str | None = None) -> str:
    """code_version's digest of the packages under `root`. `memo`: a JSON file of source digests by the
    SHA-256 of their bytes, so that only sources changed since it was written are parsed (parsing every
    source takes about a second); unreadable, it is rebuilt; written atomically, so runs may share it, and
    only into a folder that exists. `packages`: the package versions (``package_versions()``'s format) to
    digest instead of the installed ones (for a row measured elsewhere)."""
    known = _read_memo(memo)
    used: dict[str, str] = {}
    digest = hashlib.sha256((package_versions() if packages is None else packages).encode())
    for package in ("lenses", "attacks", "benchmark"):
        for path in sorted((root / package).rglob("*")):
            rel = path.relative_to(root).as_posix()
            if (not path.is_file() or "__pycache__" in path.parts or rel.endswith((".md", ".pyc"))
                    or rel.startswith(CODE_VERSION_EXCLUDES)):
                continue
            data = path.read_bytes()
            raw = hashlib.sha256(data).hexdigest()
            if rel.endswith(".py"):
                used[raw] = known.get(raw) or source_digest(data).hex()
                digest.update(rel.encode() + b"\0" + bytes.fromhex(used[raw]))
            else:
                digest.update(rel.encode() + b"\0" + bytes.fromhex(raw))
    if memo is not None and used != known:
        _write_memo(memo, used)
    return digest.hexdigest()[:16]


def _read_memo(memo: Path | None) -> dict[str, str]:
    try:
        loaded = json.loads(memo.read_text()) if memo is not None and memo.exists() else {}
    except (OSError, ValueError):
        return {}
    return {k: v for k, v in loaded.items() if isinstance(v, str) and len(v) == 64} if isinstance(loaded, dict) else {}


def _write_memo(memo: Path, digests: dict[str, str]) -> None:
    """Write the memo into its folder if that exists (the cache: a dry run creates nothing)."""
    if not memo.parent.is_dir():
        return
    try:
        tmp = memo.with_name(f"{memo.name}.{os.getpid()}.tmp")
        tmp.write_text(json.dumps(digests))
        tmp.replace(memo)
    except OSError:  # a read-only cache: the digest is still right, only slower next time
        pass


def source_digest(source: bytes) -> bytes:
    """SHA-256 of a Python source's syntax tree with its docstrings dropped (no line numbers, comments or
    layout); of the bytes themselves where it does not parse."""
    try:
        tree = ast.parse(source)
    except (SyntaxError, ValueError):
        return hashlib.sha256(source).digest()
    for node in ast.walk(tree):
        body = getattr(node, "body", None)
        if (isinstance(node, (ast.Module, ast.ClassDef, ast.FunctionDef, ast.AsyncFunctionDef)) and body
                and isinstance(body[0], ast.Expr) and isinstance(body[0].value, ast.Constant)
                and isinstance(body[0].value.value, str)):
            node.body = body[1:] or [ast.Pass()]
    return hashlib.sha256(b"ast\0" + ast.dump(tree).encode()).digest()


def package_versions() -> str:
    """'name=version;...' of the packages that shape the numbers (flat, for a flat row)."""
    out = []
    for name in _PACKAGES:
        try:
            out.append(f"{name}={version(name)}")
        except PackageNotFoundError:
            continue
    return ";".join(out)


@functools.lru_cache(maxsize=1)
def cpu_model(cpuinfo: Path = Path("/proc/cpuinfo")) -> str:
    """The CPU's model name (Linux's ``/proc/cpuinfo``), else what ``platform`` knows."""
    try:
        for line in cpuinfo.read_text(errors="replace").splitlines():
            key, _, value = line.partition(":")
            if key.strip() == "model name" and value.strip():
                return " ".join(value.split())
    except OSError:
        pass
    return platform.processor() or platform.machine()


def describe_device(device: str) -> str:
    """The device a row was measured on. For a CPU: its model, the vector instructions torch's kernels
    use (float rounding, and so the last digits of trained results, differ between AVX2 and AVX-512
    kernels) and the core count (2-core machines of one name have run 1.6x apart)."""
    if device.startswith("cuda") and torch.cuda.is_available():
        return f"{device}:{torch.cuda.get_device_name(torch.device(device))}"
    return f"cpu:{cpu_model()} ({torch.backends.cpu.get_cpu_capability()}, {os.cpu_count()} cores)"


def provenance(device: str) -> dict[str, object]:
    """The run-wide provenance fields of a row (config hash, seed and wall time are per row); `code_version`
    names what computed it, whatever the commit (the leaderboard compares entries of one version only)."""
    return {
        "code_version": code_version(),
        "git_commit": git_commit(),
        "packages": package_versions(),
        "python": platform.python_version(),
        "device": describe_device(device),
        "threads": torch.get_num_threads(),
        "date": _dt.datetime.now(_dt.timezone.utc).isoformat(timespec="seconds"),
    }
