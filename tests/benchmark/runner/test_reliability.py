"""Fault injection: a broken attacker, a corrupt cache or a second run never costs results.

Each probe has its own test; the expensive runs are shared module fixtures (smoke profile).
"""

import json
import os
import subprocess
import sys
import textwrap
import threading

import pytest

from benchmark.results.schema import read_results

pytestmark = pytest.mark.slow  # most tests run `python -m benchmark run` in a subprocess

# Timing, and provenance that names when and at which commit rather than what was measured.
TIMING = {"fit_s", "images_per_s", "wall_s", "date", "git_commit"}

PLUGINS = '''
import torch
from typing import ClassVar
from attacks import PlateRead, Reader, Restorer, ThreatModel


class Sharpen(Restorer):  # the README's example
    name: ClassVar[str] = "sharpen"
    threat_model: ClassVar[ThreatModel] = ThreatModel.SENSOR_ACCESS

    def restore(self, sensor):
        blurred = sensor.mean(dim=(2, 3), keepdim=True)
        return (2 * sensor - blurred).clamp(0, 1)


class Echo(Reader):
    """Reads every ground-truth vehicle box as the same plate."""
    name: ClassVar[str] = "echo"
    threat_model: ClassVar[ThreatModel] = ThreatModel.SENSOR_ACCESS
    hints: ClassVar[frozenset[str]] = frozenset({"vehicle_boxes"})

    def read(self, images, hints=None):
        boxes = hints.vehicle_boxes if hints and hints.vehicle_boxes else [[] for _ in images]
        return [[PlateRead("AB123", tuple(float(v) for v in box), 0.5) for box in per_image] for per_image in boxes]


class FitRaises(Restorer):
    name: ClassVar[str] = "fit-raises"
    threat_model: ClassVar[ThreatModel] = ThreatModel.SENSOR_ACCESS

    def fit(self, ctx):
        raise RuntimeError("fit exploded")

    def restore(self, sensor):
        return sensor


class RestoreRaises(Restorer):
    name: ClassVar[str] = "restore-raises"
    threat_model: ClassVar[ThreatModel] = ThreatModel.SENSOR_ACCESS

    def restore(self, sensor):
        raise RuntimeError("restore exploded")


class Nan(Restorer):
    name: ClassVar[str] = "nan"
    threat_model: ClassVar[ThreatModel] = ThreatModel.SENSOR_ACCESS

    def restore(self, sensor):
        out = sensor.clone()
        out[:, :, 0, 0] = float("nan")
        return out


class WrongShape(Restorer):
    name: ClassVar[str] = "wrong-shape"
    threat_model: ClassVar[ThreatModel] = ThreatModel.SENSOR_ACCESS

    def restore(self, sensor):
        return sensor[..., :-1]


class ReadRaises(Reader):
    name: ClassVar[str] = "read-raises"
    threat_model: ClassVar[ThreatModel] = ThreatModel.SENSOR_ACCESS

    def read(self, images, hints=None):
        raise RuntimeError("read exploded")


class Slow(Restorer):
    """A fit that would take five minutes (a lens that makes training explode)."""
    name: ClassVar[str] = "slow"
    threat_model: ClassVar[ThreatModel] = ThreatModel.SENSOR_ACCESS

    def fit(self, ctx):
        import time
        time.sleep(300)

    def restore(self, sensor):
        return sensor


class NoName(Restorer):
    threat_model: ClassVar[ThreatModel] = ThreatModel.SENSOR_ACCESS

    def restore(self, sensor):
        return sensor
'''


def benchmark_run(args, cache, cwd=None, timeout=900):
    env = {**os.environ, "PLB_CACHE": str(cache), "OMP_NUM_THREADS": "1"}
    return subprocess.run([sys.executable, "-m", "benchmark", "run", "--profile", "smoke", *args],
                          capture_output=True, text=True, timeout=timeout, env=env, cwd=cwd)


@pytest.fixture(scope="module")
def plugin_file(tmp_path_factory):
    folder = tmp_path_factory.mktemp("plugins")
    (folder / "plugins.py").write_text(PLUGINS)
    (folder / "bad_import.py").write_text("raise ImportError('this plugin needs a package that is not installed')\n")
    (folder / "dup.py").write_text(textwrap.dedent('''
        from typing import ClassVar
        from attacks import Restorer, ThreatModel

        class Dup(Restorer):
            name: ClassVar[str] = "identity"
            threat_model: ClassVar[ThreatModel] = ThreatModel.SENSOR_ACCESS

            def restore(self, sensor):
                return sensor
    '''))
    return folder


@pytest.fixture(scope="module")
def faulty_run(plugin_file, tmp_path_factory):
    """identity plus file plugins: two that work and one of each way to break."""
    out = tmp_path_factory.mktemp("faulty")
    p = plugin_file / "plugins.py"
    specs = ["identity", f"{p}:Sharpen", f"{p}:Echo", f"{p}:FitRaises", f"{p}:RestoreRaises", f"{p}:Nan",
             f"{p}:WrongShape", f"{p}:ReadRaises", f"{p}:Slow", f"{p}:NoName",
             f"{plugin_file / 'bad_import.py'}:Anything"]
    args = ["--lens", "defocus", "--out", str(out), "--budget-s", "30"]
    for spec in specs:
        args += ["--attack", spec]
    proc = benchmark_run(args, tmp_path_factory.mktemp("cache-faulty"))
    rows = read_results(out / "results.json").rows
    return proc, {(r.lens, r.attack): r for r in rows}


def test_file_plugins_give_the_rows_of_entry_points(faulty_run):
    _, rows = faulty_run
    sharpen = rows["defocus", "sharpen"]
    assert sharpen.ok and sharpen.kind == "restorer" and sharpen.metrics["psnr_db"] > 0
    for attack, kind in (("echo", "reader"), ("sharpen>echo", "chain"), ("identity>echo", "chain")):
        row = rows["defocus", attack]
        assert row.ok and row.kind == kind and row.metrics["n_plates"] >= 0, attack
    assert rows["sharp", "echo"].ok


def test_the_other_rows_are_complete(faulty_run):
    _, rows = faulty_run
    for attack in ("lens", "utility", "bound", "identity"):
        assert rows["defocus", attack].ok, attack
    assert rows["defocus", "identity"].metrics["psnr_db"] > 0


@pytest.mark.parametrize("attack, stage, text", [
    ("fit-raises", "fit", "fit exploded"),
    ("restore-raises", "restore", "restore exploded"),
    ("nan", "restore", "non-finite"),
    ("wrong-shape", "restore", "shape"),
    ("read-raises", "read", "read exploded"),
    ("slow", "fit", "budget of 30 s"),
])
def test_a_failing_attacker_is_a_failed_row_without_metrics(faulty_run, attack, stage, text):
    _, rows = faulty_run
    row = rows["defocus", attack]
    assert row.status == "failed" and not row.metrics
    assert (row.error.attacker, row.error.stage) == (attack, stage) and text in row.error.message


def test_chains_of_a_failing_reader_fail_and_failed_restorers_are_not_chained(faulty_run):
    _, rows = faulty_run
    assert rows["defocus", "sharpen>read-raises"].status == "failed"
    assert rows["sharp", "read-raises"].status == "failed"
    assert not any(a.startswith(("nan>", "wrong-shape>", "fit-raises>", "slow>")) for _, a in rows)


def test_plugins_that_fail_to_load_are_failed_rows_naming_why(faulty_run, plugin_file):
    _, rows = faulty_run
    no_name = rows["defocus", f"{plugin_file / 'plugins.py'}:NoName"]
    assert no_name.error.stage == "load" and "`name`" in no_name.error.message
    bad = rows["defocus", f"{plugin_file / 'bad_import.py'}:Anything"]
    assert bad.error.stage == "load" and "not installed" in bad.error.message


def test_the_run_exits_non_zero_with_a_summary(faulty_run):
    proc, rows = faulty_run
    assert proc.returncode == 1, proc.stderr[-2000:]
    failed = [r for r in rows.values() if not r.ok]
    assert f"{len(failed)} row(s) failed" in proc.stderr
    for attack in ("fit-raises", "restore-raises", "nan", "wrong-shape", "read-raises", "slow"):
        assert f"{attack} failed at" in proc.stderr


def test_duplicate_attacker_names_are_an_error_naming_both_sources(plugin_file, tmp_path):
    proc = benchmark_run(["--lens", "ideal", "--attack", "identity", "--attack", f"{plugin_file / 'dup.py'}:Dup",
                          "--out", str(tmp_path / "out")], tmp_path / "cache", timeout=300)
    assert proc.returncode == 2
    assert "'identity' is defined twice" in proc.stderr
    assert "dup.py:Dup" in proc.stderr and "attacks.restorers.identity" in proc.stderr
    assert not (tmp_path / "out").exists() and not (tmp_path / "cache" / "tasks").exists()


# ---- early checks ---------------------------------------------------------------------------------

def test_out_pointing_at_a_file_fails_before_any_compute(tmp_path):
    (tmp_path / "taken").write_text("")
    proc = benchmark_run(["--lens", "ideal", "--attack", "identity", "--out", str(tmp_path / "taken")],
                         tmp_path / "cache", timeout=300)
    assert proc.returncode == 2 and "is a file" in proc.stderr
    assert not (tmp_path / "cache" / "tasks").exists()


def test_unwritable_out_fails_before_any_compute(tmp_path):
    (tmp_path / "file").write_text("")
    proc = benchmark_run(["--lens", "ideal", "--attack", "identity", "--out", str(tmp_path / "file" / "sub")],
                         tmp_path / "cache", timeout=300)
    assert proc.returncode == 2 and "not a writable folder" in proc.stderr
    assert not (tmp_path / "cache" / "tasks").exists()


@pytest.mark.parametrize("option, value", [("--seeds", "0,,1"), ("--seeds", "0,"), ("--seeds", "a"),
                                           ("--seeds", "1,1"), ("--budget-s", "0"), ("--budget-s", "soon")])
def test_malformed_seeds_and_budgets_are_rejected(option, value, tmp_path):
    proc = benchmark_run(["--lens", "ideal", option, value, "--out", str(tmp_path / "o")], tmp_path / "c",
                         timeout=120)
    assert proc.returncode == 2 and option in proc.stderr


def test_a_failed_early_run_leaves_no_output_folder(tmp_path):
    proc = benchmark_run(["--lens", "idael"], tmp_path / "cache", cwd=tmp_path, timeout=120)
    assert proc.returncode == 2 and "unknown lens" in proc.stderr
    assert not (tmp_path / "runs").exists()


def test_a_bad_lens_spec_field_is_named_before_any_compute(tmp_path):
    spec = tmp_path / "glass.toml"
    spec.write_text('name = "glass"\n[optics]\nmask_material = ["glass"]\n')
    proc = benchmark_run(["--lens", str(spec), "--attack", "identity", "--out", str(tmp_path / "o")],
                         tmp_path / "cache", timeout=120)
    assert proc.returncode == 2 and "mask_material" in proc.stderr, proc.stderr[-2000:]
    assert not (tmp_path / "o").exists()


# ---- a cache shared by runs -----------------------------------------------------------------------

@pytest.fixture(scope="module")
def shared_cache_runs(tmp_path_factory):
    """Two runs started at once on one cache."""
    cache, outs = tmp_path_factory.mktemp("shared-cache"), [tmp_path_factory.mktemp(f"run{i}") for i in range(2)]
    procs: list = [None, None]

    def start(i):
        procs[i] = benchmark_run(["--lens", "defocus", "--attack", "identity", "--attack", "lpdr-oracle",
                                  "--out", str(outs[i])], cache)

    threads = [threading.Thread(target=start, args=(i,)) for i in range(2)]
    for t in threads:
        t.start()
    for t in threads:
        t.join()
    return cache, outs, procs


def timing(key):
    return key in TIMING or key.endswith("_s_per_image")


def measured(out):
    """What a run measured: rows without timing or dates."""
    rows = []
    for r in read_results(out / "results.json").rows:
        d = r.to_json()
        for part in ("metrics", "intervals", "provenance"):
            d[part] = {k: v for k, v in d[part].items() if not timing(k)}
        rows.append(d)
    return rows


def test_two_runs_on_one_cache_both_complete_and_agree(shared_cache_runs):
    _, outs, procs = shared_cache_runs
    for proc in procs:
        assert proc.returncode == 0, proc.stderr[-3000:]
    a, b = measured(outs[0]), measured(outs[1])
    assert a == b and len(a) >= 8


def test_results_with_failures_are_not_reused_by_a_later_run(tmp_path, monkeypatch):
    from benchmark.runner import tasks
    from benchmark.runner.planning import Task
    from benchmark.store.profiles import get_profile
    from benchmark.runner.config import RunConfig
    from benchmark.results.schema import Row, RowError

    calls = []

    def body(task, cfg, staging):  # fails the first time, as a plugin fixed in between would
        calls.append(task.key)
        if len(calls) == 1:
            return tasks.TaskResult([Row.failed("lens", "l", "lens", 0, "smoke", "s", RowError("x", "fit", "boom"))])
        return tasks.TaskResult([Row(kind="lens", attack="lens", lens="l", seed=0, profile="smoke", scenes="s")])

    monkeypatch.setitem(tasks._KINDS, "test-kind", body)
    task = Task("test-kind", 0)
    # execute records each computed task's cost under the run's profile (benchmark.runner.task_costs)
    cfg = RunConfig(lenses=[], attacks=None, scenes="s", profile=get_profile("smoke"), seeds=[0], cache_dir=tmp_path)
    assert tasks.execute(task, cfg, tmp_path).has_failures
    assert not tasks.execute(task, cfg, tmp_path).has_failures  # computed again: now it works
    assert not tasks.execute(task, cfg, tmp_path).has_failures and len(calls) == 2  # and then reused


def test_corrupt_task_results_are_reported_and_rebuilt(shared_cache_runs, tmp_path):
    cache, outs, _ = shared_cache_runs
    results = sorted((cache / "tasks").rglob("result.json"))
    assert results
    for path in results:  # truncate every stored task result
        path.write_bytes(path.read_bytes()[: len(path.read_bytes()) // 2])
    proc = benchmark_run(["--lens", "defocus", "--attack", "identity", "--attack", "lpdr-oracle",
                          "--out", str(tmp_path / "again")], cache)
    assert proc.returncode == 0, proc.stderr[-3000:]
    for path in results:
        assert str(path) in proc.stderr  # reported with its path
        json.loads(path.read_text())     # and rebuilt
    assert measured(tmp_path / "again") == measured(outs[0])


@pytest.mark.slow
def test_a_lens_task_that_fails_gives_that_lens_failed_rows_and_the_run_completes(tmp_path, monkeypatch):
    """A lens whose own task raises (a spec that runs out of memory, say) must not end the run while its
    partial results are written: the other lens's rows are complete and results.json is written."""
    import benchmark
    from benchmark.runner import tasks

    real = tasks._KINDS["lens"]

    def lens_task(task, cfg, staging):
        if task.lens == "defocus":
            raise MemoryError("the lens task of defocus ran out of memory")
        return real(task, cfg, staging)

    monkeypatch.setitem(tasks._KINDS, "lens", lens_task)
    monkeypatch.setenv("PLB_CACHE", str(tmp_path / "cache"))
    benchmark.run(lenses=["ideal", "defocus"], attacks=["identity"], profile="smoke", out=tmp_path / "out")
    rows = read_results(tmp_path / "out" / "results.json").rows
    lens_rows = {r.lens: r for r in rows if r.kind == "lens"}
    assert not lens_rows["defocus"].ok and "ran out of memory" in lens_rows["defocus"].error.message
    assert lens_rows["ideal"].ok
    assert [r.attack for r in rows if r.lens == "ideal" and r.kind == "restorer" and r.ok] == ["identity"]
