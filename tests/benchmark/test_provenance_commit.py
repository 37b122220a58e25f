"""The commit stamped on results is read once per process, when the run starts."""

import subprocess

from benchmark import provenance


def test_commit_is_read_once_per_process(monkeypatch):
    provenance.git_commit.cache_clear()
    first = provenance.git_commit()
    calls = []
    monkeypatch.setattr(subprocess, "run", lambda *a, **k: calls.append(a) or (_ for _ in ()).throw(OSError()))
    assert provenance.git_commit() == first and calls == []  # a later HEAD would not be consulted
    provenance.git_commit.cache_clear()
    assert provenance.git_commit() == "unknown" and calls  # without the cache it would be
    monkeypatch.undo()
    provenance.git_commit.cache_clear()
