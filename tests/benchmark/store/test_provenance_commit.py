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


def test_code_version_follows_what_results_depend_on(tmp_path):
    files = {"lenses/optics.py": "a", "attacks/readers/lpdr.py": "b", "benchmark/runner/tasks.py": "c",
             "benchmark/publish/report.py": "d", "benchmark/studies/s.py": "e", "benchmark/cli.py": "f",
             "benchmark/results/charts/plot.py": "g", "attacks/README.md": "h", "attacks/weights/w.safetensors": "i",
             "benchmark/store/measured_costs.json": "j", "benchmark/store/profiles.json": "k"}
    for rel, text in files.items():
        (tmp_path / rel).parent.mkdir(parents=True, exist_ok=True)
        (tmp_path / rel).write_text(text)
    base = provenance.code_digest(tmp_path)
    for rel in ("benchmark/publish/report.py", "benchmark/studies/s.py", "benchmark/cli.py",
                "benchmark/results/charts/plot.py", "attacks/README.md", "benchmark/store/measured_costs.json"):
        (tmp_path / rel).write_text("changed")
        assert provenance.code_digest(tmp_path) == base, rel
    for rel in ("lenses/optics.py", "attacks/readers/lpdr.py", "benchmark/runner/tasks.py", "attacks/weights/w.safetensors",
                "benchmark/store/profiles.json"):  # a table beside the quoted costs still counts
        before = provenance.code_digest(tmp_path)
        (tmp_path / rel).write_text("changed")
        assert provenance.code_digest(tmp_path) != before, rel
    (tmp_path / "benchmark/results/new.py").write_text("x")  # a new source file counts too
    assert provenance.code_digest(tmp_path) != before
    assert len(provenance.code_version()) == 16


def test_a_comment_docstring_or_layout_edit_keeps_the_code_version_and_a_statement_edit_does_not(tmp_path):
    source = tmp_path / "attacks" / "a.py"
    source.parent.mkdir(parents=True)
    source.write_text('"""Module."""\n\ndef f(x):\n    """Doubles."""\n    return 2 * x  # twice\n')
    base = provenance.code_digest(tmp_path)
    for same in ('"""Module, reworded."""\ndef f(x):\n    return 2 * x\n',
                 '# a new comment\n"""Module."""\n\n\ndef f(x):\n    """Doubles x."""\n\n    return 2*x\n'):
        source.write_text(same)
        assert provenance.code_digest(tmp_path) == base, same
    for other in ('def f(x):\n    return 3 * x\n', 'def f(x):\n    "x"\n    return 2 * x\n    "y"\n',
                  'def f(x):\n    return 2 * x +\n'):  # the last does not parse: its bytes count
        source.write_text(other)
        assert provenance.code_digest(tmp_path) != base, other


def test_the_source_digest_memo_is_used_and_rebuilt_when_unreadable(tmp_path, monkeypatch):
    source = tmp_path / "lenses" / "optics.py"
    source.parent.mkdir(parents=True)
    source.write_text("x = 1\n")
    memo = tmp_path / "cache" / "code-digests.json"
    assert provenance.code_digest(tmp_path, memo=memo) == provenance.code_digest(tmp_path)
    assert not memo.parent.exists()  # no cache folder: none is made (a dry run creates nothing)
    memo.parent.mkdir()
    base = provenance.code_digest(tmp_path, memo=memo)
    assert provenance.code_digest(tmp_path) == base and memo.exists()
    parsed = []
    real = provenance.source_digest
    monkeypatch.setattr(provenance, "source_digest", lambda data: parsed.append(data) or real(data))
    assert provenance.code_digest(tmp_path, memo=memo) == base and parsed == []  # read from the memo
    memo.write_text("{not json")
    assert provenance.code_digest(tmp_path, memo=memo) == base and len(parsed) == 1  # parsed again, memo rewritten
    assert provenance.code_digest(tmp_path, memo=memo) == base and len(parsed) == 1
