"""What the cache's files look like to other users and what it does with symbolic links:
modes follow the umask, a symlinked lock is refused, a symlinked root is followed."""

import os
import re
import stat

import pytest

from benchmark.store.cache import (ArtifactCache, UnsafeLockError, atomic_write_text, exclusive, write_verified)


@pytest.fixture
def umask():
    """Set the process umask for one test and put the old one back."""
    old = os.umask(0o022)
    yield lambda mask: os.umask(mask)
    os.umask(old)


def _mode(path) -> int:
    return stat.S_IMODE(os.stat(path).st_mode)


@pytest.mark.parametrize("mask, expected", [(0o022, 0o644), (0o002, 0o664), (0o077, 0o600)])
def test_written_files_follow_the_umask(tmp_path, umask, mask, expected):
    umask(mask)
    text = tmp_path / "results.json"
    atomic_write_text(text, "{}")
    artifact = write_verified(tmp_path / "kind" / "a.safetensors", b"data")
    with exclusive(tmp_path / ".task.lock"):
        pass
    for path in (text, artifact, artifact.with_name(artifact.name + ".sha256"), tmp_path / ".task.lock"):
        assert _mode(path) == expected, path
    # No temporary file is left beside them.
    assert sorted(p.name for p in tmp_path.iterdir()) == [".task.lock", "kind", "results.json"]


def test_a_symlinked_lock_is_refused_and_its_target_never_created(tmp_path):
    target = tmp_path / "elsewhere" / "victim"
    target.parent.mkdir()
    lock = tmp_path / "cache" / ".task.lock"
    lock.parent.mkdir()
    lock.symlink_to(target)
    with pytest.raises(UnsafeLockError) as refused:
        with exclusive(lock):
            pytest.fail("the lock was taken through a symlink")
    assert refused.value.filename == str(lock)  # an OSError's path and reason: what the CLI prints
    assert re.fullmatch(r"this lock file is a symbolic link \(to .*victim\); refusing .* Remove the link.*",
                        refused.value.strerror)
    assert not target.exists()
    # A link to an existing file leaves that file as it was.
    target.write_bytes(b"precious")
    with pytest.raises(UnsafeLockError):
        with exclusive(lock):
            pass
    assert target.read_bytes() == b"precious" and lock.is_symlink()


def test_a_fifo_under_a_locks_name_is_refused(tmp_path):
    lock = tmp_path / ".task.lock"
    os.mkfifo(lock)
    with pytest.raises(UnsafeLockError, match="not a regular file"):
        with exclusive(lock):
            pass


def test_a_symlinked_cache_root_is_followed(tmp_path):
    # Documented: the root (PLB_CACHE) may be a link to another disk; artifacts land in its target.
    disk = tmp_path / "disk"
    disk.mkdir()
    root = tmp_path / "cache"
    root.symlink_to(disk, target_is_directory=True)
    store = ArtifactCache(root)
    path = store.save("nafnet", {"seed": 0}, b"weights")
    with exclusive(root / "nafnet" / ".x.lock"):
        assert store.load("nafnet", {"seed": 0}) == b"weights"
    assert (disk / path.relative_to(root)).read_bytes() == b"weights"
