"""The artifact cache: content-addressed by config hash, written atomically, verified on read.

Several runs (processes, Ray workers, nodes) may share one cache folder (`PLB_CACHE`):

- every file is written to a temporary name and renamed, so a reader sees the old file or the
  whole new one;
- a verified artifact carries a SHA-256 sidecar (`<name>.sha256`), written after the data; a
  read checks it, and a missing, truncated or corrupt artifact is reported with its path,
  removed and read as absent, so its producer rebuilds it;
- typed forms of the same (`write_verified_json` / `read_verified_json`, `..._tensors` for
  safetensors, `..._checkpoint` for torch checkpoints read with `weights_only=True`) also treat
  bytes that match their checksum but cannot be parsed (an older layout) as absent, reported;
- `seal(path)` gives a file written by another library (a matplotlib chart) the same sidecar;
- `exclusive(path)` is a per-task lock (an OS file lock, released by the kernel when its holder
  dies, so a crashed run never leaves a stale lock behind).

Files are created readable as the user's umask allows (0644 under the usual 022), as `open()`
would, so a cache, a run's results or the leaderboard page can be shared with other users or
served; `tempfile` alone would leave every atomically written file 0600.

Symbolic links: a lock file that is a symlink is refused (`UnsafeLockError`): opening it would
create or touch whatever file it points at, with the rights of whoever runs the benchmark. The
cache root (`PLB_CACHE`, or the default folder) and the folders in it are followed when they are
symlinks: that is how a cache is moved to another disk, and whoever can plant a link in the cache
can already rewrite what it holds. A shared cache must therefore be writable only by users who
are trusted with each other's runs (a group folder, not a world-writable one).
"""

from __future__ import annotations

import contextlib
import errno
import fcntl
import hashlib
import io
import json
import logging
import os
import stat
import tempfile
from collections.abc import Callable, Iterator, Mapping
from pathlib import Path
from typing import TYPE_CHECKING, Any, TypeVar

if TYPE_CHECKING:
    import torch

T = TypeVar("T")

log = logging.getLogger(__name__)

CHECKSUM_SUFFIX = ".sha256"


def cache_root() -> Path:
    """`$PLB_CACHE`, else ~/.cache/privacy-lens-bench."""
    return Path(os.environ.get("PLB_CACHE") or Path.home() / ".cache" / "privacy-lens-bench")


def config_hash(config: Any, length: int = 16) -> str:
    """Stable hash of a JSON-serialisable config (sorted keys, no whitespace)."""
    text = json.dumps(config, sort_keys=True, separators=(",", ":"), default=str)
    return hashlib.sha256(text.encode()).hexdigest()[:length]


def _umask() -> int:
    """The process's umask, read without changing it where the OS allows (Linux: /proc), since
    setting it to read it would briefly give other threads' new files the wrong mode."""
    try:
        for line in Path("/proc/self/status").read_text().splitlines():
            if line.startswith("Umask:"):
                return int(line.split()[1], 8)
    except (OSError, ValueError, IndexError):
        pass
    mask = os.umask(0o022)
    os.umask(mask)
    return mask


def atomic_write_bytes(path: Path, data: bytes) -> None:
    """Write `data` to `path` so that readers see the old file or the whole new one, never a part.

    The file gets the mode `open()` would give it (0666 less the umask), not mkstemp's private 0600."""
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    fd, tmp = tempfile.mkstemp(dir=path.parent, prefix=f".{path.name}.", suffix=".tmp")
    try:
        os.fchmod(fd, 0o666 & ~_umask())
        with os.fdopen(fd, "wb") as f:
            f.write(data)
            f.flush()
            os.fsync(f.fileno())
        os.replace(tmp, path)
    except BaseException:
        Path(tmp).unlink(missing_ok=True)
        raise


def atomic_write_text(path: Path, text: str) -> None:
    atomic_write_bytes(path, text.encode("utf-8"))


def _checksum_path(path: Path) -> Path:
    return path.with_name(path.name + CHECKSUM_SUFFIX)


def write_verified(path: Path, data: bytes) -> Path:
    """Write `data` atomically, then its SHA-256 sidecar (a reader trusts the data only with it)."""
    path = Path(path)
    atomic_write_bytes(path, data)
    atomic_write_text(_checksum_path(path), hashlib.sha256(data).hexdigest() + "\n")
    return path


def read_verified(path: Path) -> bytes | None:
    """The bytes of an artifact written by `write_verified`, or None when it is absent.

    A file without its checksum, or whose bytes do not match it (truncated, overwritten), is
    reported with its path and removed, and reads as absent: the caller rebuilds it.
    """
    path = Path(path)
    try:
        data = path.read_bytes()
    except FileNotFoundError:
        return None
    try:
        expected = _checksum_path(path).read_text().strip()
    except FileNotFoundError:
        expected = ""
    actual = hashlib.sha256(data).hexdigest()
    if actual == expected:
        return data
    reason = "has no checksum" if not expected else f"does not match its checksum ({len(data)} bytes)"
    log.warning("corrupt cache artifact %s: %s; removing it, it will be rebuilt", path, reason)
    discard(path)
    return None


def seal(path: Path) -> Path:
    """Write the SHA-256 sidecar of a file already written in full (by a library that writes files
    itself), so `read_verified` trusts it."""
    path = Path(path)
    atomic_write_text(_checksum_path(path), hashlib.sha256(path.read_bytes()).hexdigest() + "\n")
    return path


def _read_parsed(path: Path, parse: Callable[[bytes], T], what: str) -> T | None:
    """`parse(bytes)` of a verified artifact, or None when absent, corrupt or unparsable (reported, removed)."""
    data = read_verified(path)
    if data is None:
        return None
    try:
        return parse(data)
    except Exception as exc:  # json, safetensors and torch each raise their own types for bad bytes
        log.warning("unreadable cache artifact %s (%s: %s); removing it, it will be rebuilt", path, what, exc)
        discard(path)
        return None


def write_verified_json(path: Path, data: Any) -> Path:
    """`data` as indented JSON (non-finite floats as NaN/Infinity), verified."""
    return write_verified(path, json.dumps(data, indent=1, default=float).encode())


def read_verified_json(path: Path) -> Any | None:
    """The JSON written by `write_verified_json`, or None (absent, or corrupt: reported and removed)."""
    return _read_parsed(path, json.loads, "JSON")


def write_verified_tensors(path: Path, tensors: Mapping[str, torch.Tensor]) -> Path:
    """Tensors (contiguous, CPU) as a safetensors file, verified."""
    from safetensors.torch import save  # torch-backed helpers import it lazily: the CLI starts without torch
    return write_verified(path, save(dict(tensors)))


def read_verified_tensors(path: Path) -> dict[str, torch.Tensor] | None:
    """The tensors of a `write_verified_tensors` file, or None (absent, or corrupt: reported and removed)."""
    from safetensors.torch import load
    return _read_parsed(path, load, "safetensors")


def write_verified_checkpoint(path: Path, state: Mapping[str, Any]) -> Path:
    """A checkpoint of tensors, numbers, strings, lists and dicts (`torch.save`), verified."""
    import torch
    buffer = io.BytesIO()
    torch.save(dict(state), buffer)
    return write_verified(path, buffer.getvalue())


def read_verified_checkpoint(path: Path) -> dict[str, Any] | None:
    """The checkpoint of `write_verified_checkpoint` on the CPU, read with `weights_only=True` (never
    unpickled), or None (absent, or corrupt: reported and removed)."""
    import torch
    return _read_parsed(path, lambda data: torch.load(io.BytesIO(data), map_location="cpu", weights_only=True),
                        "torch checkpoint")


def discard(path: Path) -> None:
    """Remove an artifact and its checksum (when a reader found it corrupt)."""
    Path(path).unlink(missing_ok=True)
    _checksum_path(Path(path)).unlink(missing_ok=True)


class UnsafeLockError(OSError):
    """A lock file is a symbolic link (or not a regular file): taking it would write elsewhere. Its
    `filename` is the lock's path and its `strerror` says what to do (the CLI prints both)."""


def _open_lock(lock_path: Path) -> int:
    """A descriptor of the lock file, created if needed (mode from the umask), never through a symlink."""
    try:
        fd = os.open(lock_path, os.O_RDWR | os.O_CREAT | os.O_NOFOLLOW | os.O_CLOEXEC, 0o666)
    except OSError as exc:
        # O_NOFOLLOW on a symlink fails with ELOOP (EMLINK on some BSDs).
        if lock_path.is_symlink():
            raise UnsafeLockError(
                errno.ELOOP, f"this lock file is a symbolic link (to {os.readlink(lock_path)}); refusing to follow "
                "it, since taking the lock would create or open that file. Remove the link: locks are regular files "
                "the benchmark creates itself", str(lock_path)) from exc
        raise
    if not stat.S_ISREG(os.fstat(fd).st_mode):  # a FIFO or device planted under the lock's name
        os.close(fd)
        raise UnsafeLockError(errno.EINVAL, "this lock file is not a regular file; remove it (locks are regular "
                              "files the benchmark creates itself)", str(lock_path))
    return fd


@contextlib.contextmanager
def exclusive(lock_path: Path) -> Iterator[None]:
    """Hold an exclusive lock on `lock_path` (created if needed) for the block; waits for it.

    The lock is the kernel's (flock): it dies with its holder, so no stale lock can block a later run.
    A lock file that is a symlink raises `UnsafeLockError` (see the module docstring). Not reentrant:
    a process that takes the same lock twice waits for itself.
    """
    lock_path = Path(lock_path)
    lock_path.parent.mkdir(parents=True, exist_ok=True)
    fd = _open_lock(lock_path)
    try:
        fcntl.flock(fd, fcntl.LOCK_EX)
        try:
            yield
        finally:
            fcntl.flock(fd, fcntl.LOCK_UN)
    finally:
        os.close(fd)


class ArtifactCache:
    """`attacks.base.ArtifactStore` over a folder: `<root>/<kind>/<config hash of key><suffix>`, verified."""

    def __init__(self, root: Path, suffix: str = ".safetensors"):
        self.root = Path(root)
        self.suffix = suffix

    def path(self, kind: str, key: Mapping[str, Any]) -> Path:
        """Where the artifact of (kind, key) lives."""
        return self.root / kind / f"{config_hash(dict(key))}{self.suffix}"

    def load(self, kind: str, key: Mapping[str, Any]) -> bytes | None:
        """The verified bytes of (kind, key), or None (absent, or corrupt and removed)."""
        return read_verified(self.path(kind, key))

    def save(self, kind: str, key: Mapping[str, Any], data: bytes) -> Path:
        """Store `data` as the artifact of (kind, key)."""
        return write_verified(self.path(kind, key), data)
