"""The commit stamped on results is read once per process, when the run starts; the CPU is named with
its model, torch's vector instructions and its cores."""

import os
import subprocess

import torch

from benchmark.store import provenance


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


def test_the_cpu_is_named_by_model_instructions_and_cores(tmp_path):
    info = tmp_path / "cpuinfo"
    info.write_text("processor\t: 0\nvendor_id\t: GenuineIntel\nmodel name\t: Intel(R)  Xeon(R) Gold 6338\n"
                    "processor\t: 1\nmodel name\t: Intel(R)  Xeon(R) Gold 6338\n")
    assert provenance.cpu_model.__wrapped__(info) == "Intel(R) Xeon(R) Gold 6338"
    assert provenance.cpu_model.__wrapped__(tmp_path / "missing") != ""  # falls back to platform
    described = provenance.describe_device("cpu")
    assert described.startswith(f"cpu:{provenance.cpu_model()} (")
    assert f"({torch.backends.cpu.get_cpu_capability()}, {os.cpu_count()} cores)" in described
