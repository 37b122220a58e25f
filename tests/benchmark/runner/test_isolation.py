"""No attacker reaches another's inputs or outputs, no plugin ends the run
with nothing written, a lens that fails takes nothing else with it, and no cached picture is reused
or published unchecked.

The two smoke runs are one module fixture: the first is killed by a restorer (SIGKILL, as the kernel's
OOM killer would) and must leave its finished rows on disk; the second resumes and completes.
"""

import hashlib
import json
import os
import signal
import subprocess
import sys

import pytest
import torch

import attacks
from benchmark.results.schema import read_results

HOSTILE = '''
import os, signal
from pathlib import Path
from attacks import Reader, Restorer, ThreatModel


class CopyBefore(Restorer):
    name = "copy-before"; threat_model = ThreatModel.SENSOR_ACCESS
    def restore(self, s): return s.clone()


class Mutate(Restorer):  # the probe: writes into its input
    name = "mutate"; threat_model = ThreatModel.SENSOR_ACCESS
    def restore(self, s): s.zero_(); return s


class CopyAfter(CopyBefore):
    name = "copy-after"


class Exit(Restorer):
    name = "exit"; threat_model = ThreatModel.SENSOR_ACCESS
    def restore(self, s): raise SystemExit(3)


class Desc(Restorer):
    name = "desc"; threat_model = ThreatModel.SENSOR_ACCESS
    def describe(self): raise RuntimeError("x")
    def restore(self, s): return s


class KillOnce(Restorer):
    """Dies as a process killed for memory would, the first time only."""
    name = "kill-once"; threat_model = ThreatModel.SENSOR_ACCESS
    def restore(self, s):
        marker = Path(os.environ["PLB_TEST_KILLED"])
        if not marker.exists():
            marker.write_text("")
            os.kill(os.getpid(), signal.SIGKILL)
        return s.clone()


class ZeroReader(Reader):  # writes into the images it reads (a restorer's output, read by others too)
    name = "zero-reader"; threat_model = ThreatModel.SENSOR_ACCESS
    def read(self, images, hints=None):
        images.zero_()
        return [[] for _ in images]


class Witness(Reader):
    """Records the sum of every batch it is handed, after zero-reader read the same images."""
    name = "witness"; threat_model = ThreatModel.SENSOR_ACCESS
    def read(self, images, hints=None):
        with open(os.environ["PLB_TEST_WITNESS"], "a") as f:
            f.write(f"{float(images.sum())}\\n")
        return [[] for _ in images]


class DescReader(Reader):
    name = "desc-reader"; threat_model = ThreatModel.SENSOR_ACCESS
    def describe(self): raise SystemExit(4)
    def read(self, images, hints=None): return [[] for _ in images]


class Linger(Reader):
    """Leaves an endless non-daemon thread and a child process behind, once a process."""
    name = "linger"; threat_model = ThreatModel.SENSOR_ACCESS
    started = False
    def read(self, images, hints=None):
        import subprocess, sys, threading, time
        if not Linger.started:
            Linger.started = True
            child = subprocess.Popen([sys.executable, "-c", "import time; time.sleep(900)"])
            with open(os.environ["PLB_TEST_CHILDREN"], "a") as f:
                f.write(f"{child.pid}\\n")
            threading.Thread(target=time.sleep, args=(900,), name="linger-thread").start()
        return [[] for _ in images]
'''
ATTACKS = ["CopyBefore", "Mutate", "CopyAfter", "identity", "Exit", "Desc", "KillOnce", "ZeroReader", "Witness",
           "DescReader", "Linger"]


def smoke_run(args, cache, env=None, timeout=600):
    env = {**os.environ, "PLB_CACHE": str(cache), "OMP_NUM_THREADS": "1", **(env or {})}
    return subprocess.run([sys.executable, "-m", "benchmark", "run", "--profile", "smoke", *args],
                          capture_output=True, text=True, timeout=timeout, env=env)


@pytest.fixture(scope="module")
def runs(tmp_path_factory):
    """(killed run, its out folder, resumed run, its out folder, cache, witness file)."""
    root = tmp_path_factory.mktemp("hostile")
    (root / "p.py").write_text(HOSTILE)
    args = ["--lens", "ideal", "--no-isolate"]  # the guards of the runner's own process (plugins isolated: sandbox/)
    for name in ATTACKS:
        args += ["--attack", name if name == "identity" else f"{root / 'p.py'}:{name}"]
    env = {"PLB_TEST_KILLED": str(root / "killed"), "PLB_TEST_WITNESS": str(root / "witness.txt"),
           "PLB_TEST_CHILDREN": str(root / "children.txt")}
    killed = smoke_run([*args, "--out", str(root / "out1")], root / "cache", env)
    from benchmark.runner.tasks import TaskResult
    # A task with a failed row (sharp: desc-reader) is recomputed by design; the others must be reused.
    task_files = {p: p.stat().st_mtime_ns for p in (root / "cache" / "tasks").rglob("result.json")
                  if not TaskResult.from_json(json.loads(p.read_text())).has_failures}
    (root / "witness.txt").unlink(missing_ok=True)  # the second run's reads only
    resumed = smoke_run([*args, "--out", str(root / "out2")], root / "cache", env)
    return {"killed": killed, "out1": root / "out1", "resumed": resumed, "out2": root / "out2",
            "cache": root / "cache", "witness": root / "witness.txt", "task_files": task_files,
            "children": root / "children.txt"}


def rows_of(out):
    return {(r.lens, r.attack): r for r in read_results(out / "results.json").rows}


@pytest.mark.slow
def test_a_killed_run_leaves_every_finished_tasks_rows_on_disk(runs):
    assert runs["killed"].returncode == -signal.SIGKILL, runs["killed"].stderr[-2000:]
    partial = read_results(runs["out1"] / "results.partial.json")
    assert partial.meta["partial"] is True and 0 < partial.meta["tasks_done"] < partial.meta["tasks_total"]
    kinds = {(r.lens, r.kind) for r in partial.rows}
    assert {("ideal", "lens"), ("ideal", "utility"), ("ideal", "bound"), ("sharp", "reader")} <= kinds
    assert not (runs["out1"] / "results.json").exists()


@pytest.mark.slow
def test_the_rerun_resumes_from_the_finished_tasks_and_completes(runs):
    assert runs["resumed"].returncode == 1, runs["resumed"].stderr[-3000:]  # exit and desc fail
    assert len(runs["task_files"]) >= 4  # the killed run's finished tasks (lens, utility, bound, ...) ...
    for path, mtime in runs["task_files"].items():
        assert path.stat().st_mtime_ns == mtime, f"{path} was recomputed"  # ... are reused as they are
    assert (runs["out2"] / "results.json").exists() and not (runs["out2"] / "results.partial.json").exists()
    assert rows_of(runs["out2"])["ideal", "kill-once"].ok


@pytest.mark.slow
def test_a_restorer_writing_into_its_input_changes_no_other_score(runs):
    rows = rows_of(runs["out2"])
    before, after = rows["ideal", "copy-before"], rows["ideal", "copy-after"]
    assert before.ok and after.ok and rows["ideal", "mutate"].ok
    assert after.metrics["psnr_db"] == before.metrics["psnr_db"] > 10
    assert rows["ideal", "identity"].metrics["psnr_db"] > 15  # 6.98 dB when it read zeroed images


@pytest.mark.slow
def test_a_reader_writing_into_what_it_reads_changes_nothing_another_reads(runs):
    sums = [float(line) for line in runs["witness"].read_text().split()]
    # In plan order, each read after zero-reader's: the sharp windows (task `sharp`), then the sensor,
    # copy-before, mutate (zeros of its own making), copy-after, identity, kill-once; batches alike.
    per = len(sums) // 7
    assert per >= 1 and len(sums) == 7 * per
    sharp, sensor, before, mutate, after, identity, kill = (sums[i * per:(i + 1) * per] for i in range(7))
    assert mutate == [0.0] * per
    assert all(s > 0 for s in sharp + sensor + before + after + identity + kill)
    assert sensor == before == after == kill  # three copies of the sensor, read unchanged each time
    rows = rows_of(runs["out2"])
    assert rows["ideal", "copy-before>witness"].ok and rows["ideal", "copy-before>zero-reader"].ok


@pytest.mark.slow
def test_a_plugin_system_exit_and_a_raising_describe_are_failed_rows(runs):
    rows = rows_of(runs["out2"])
    exit_row, desc = rows["ideal", "exit"], rows["ideal", "desc"]
    assert (exit_row.status, exit_row.error.stage, exit_row.error.message) == ("failed", "restore", "SystemExit: 3")
    assert desc.status == "failed" and desc.error.stage == "load"
    assert desc.error.message == "desc.describe() failed: RuntimeError: x"
    for attack in ("desc-reader", "copy-before>desc-reader"):
        assert "desc-reader.describe() failed: SystemExit: 4" in rows["ideal", attack].error.message
    assert rows["sharp", "desc-reader"].status == "failed"
    assert "exit failed at restore: SystemExit: 3" in runs["resumed"].stderr
    ok = {a for (lens, a), r in rows.items() if r.ok and lens == "ideal"}
    assert {"lens", "utility", "bound", "identity", "copy-after", "identity>witness", "witness"} <= ok


def running(pid: int) -> bool:
    """Whether process `pid` exists and is not a zombie (an exited child whose parent died unreaped stays
    one where the container's init does not reap)."""
    try:
        with open(f"/proc/{pid}/stat") as f:
            return f.read().rsplit(")", 1)[1].split()[0] != "Z"
    except FileNotFoundError:
        return False


@pytest.mark.slow
def test_a_plugins_child_and_thread_do_not_outlive_its_call_or_hold_the_exit(runs):
    """The resumed run would wait 900 s for linger's thread (the run's timeout is 600 s): it ends once its
    results are written, and the child linger started is ended when the read that started it returns."""
    assert (runs["out2"] / "results.json").exists()
    pids = [int(x) for x in runs["children"].read_text().split()]
    assert len(pids) == 2  # one per run (the first was killed after linger's read)
    assert not [pid for pid in pids if running(pid)]
    err = runs["resumed"].stderr
    assert "attacker 'linger' left 1 child process(es) running after read" in err
    assert "attacker 'linger' left 1 thread(s) running after read (linger-thread)" in err
    assert "ending the process without waiting for the plugin thread(s) linger: linger-thread" in err


@pytest.mark.slow
def test_every_task_picture_is_sealed_and_the_run_copies_match(runs):
    pictures = [p for p in (runs["cache"] / "tasks").rglob("*.png") if ".staging-" not in str(p.parent)]
    assert pictures
    for picture in pictures:
        expected = picture.with_name(picture.name + ".sha256").read_text().strip()
        assert hashlib.sha256(picture.read_bytes()).hexdigest() == expected
        copied = runs["out2"] / picture.name
        assert copied.read_bytes() == picture.read_bytes()


# ---- in-process: the copies themselves ------------------------------------------------------------

class ZeroRestorer(attacks.Restorer):
    name = "zero"
    threat_model = attacks.ThreatModel.SENSOR_ACCESS

    def restore(self, sensor):
        sensor.zero_()
        return sensor


class ZeroReader(attacks.Reader):
    name = "zero-reader"
    threat_model = attacks.ThreatModel.SENSOR_ACCESS

    def read(self, images, hints=None):
        images.zero_()
        return [[] for _ in images]


def test_restore_and_read_hand_out_copies():
    from benchmark.runner.evaluation import read_plates, restore_all, restore_windows
    sensor = torch.rand(3, 3, 8, 8)
    kept = sensor.clone()
    restore_all(ZeroRestorer(), sensor, 2, "cpu")
    windows = list(sensor)
    restore_windows(ZeroRestorer(), windows, 2, "cpu")
    assert torch.equal(sensor, kept)
    from benchmark.scenes.records import Scene
    scenes = [Scene(image=sensor[i].permute(1, 2, 0).numpy(), labels=None, plates=[], vehicles=[], seed=i,
                    name=f"s{i}") for i in range(3)]
    read_plates(ZeroReader(), sensor, scenes, 2, "cpu")
    read_plates(ZeroReader(), windows, scenes, 2, "cpu")
    assert torch.equal(sensor, kept)


def test_each_attacker_gets_its_own_lens_and_adversary():
    import lenses
    from attacks.networks import RED10
    from benchmark.runner.isolation import own_context
    lens = lenses.load("defocus")
    object.__setattr__(lens, "adversary", RED10(width=4))
    shared = attacks.FitContext(lens=lens, adversary=lens.adversary)
    before = [p.clone() for p in shared.adversary.parameters()]
    mine = own_context(shared, "mine")
    assert mine.lens.adversary is mine.adversary  # one copy: the copied lens holds the copied adversary
    with torch.no_grad():
        for p in [*mine.lens.parameters(), *mine.adversary.parameters()]:
            p.zero_()
    assert torch.equal(shared.lens.psf(), lenses.load("defocus").psf())
    assert all(torch.equal(a, b) for a, b in zip(shared.adversary.parameters(), before))


# ---- a lens that fails; pictures -----------------------------------------------------------------

@pytest.mark.slow
def test_a_spec_the_sensor_cannot_represent_is_named_before_any_compute(tmp_path):
    spec = tmp_path / "bits.toml"
    spec.write_text('name = "bits"\n[mask]\nzernike_um = [0, 0, 0, 0.2, 0, 0]\n[sensor]\nadc_bits = 1000\n')
    proc = smoke_run(["--lens", "ideal", "--lens", str(spec), "--out", str(tmp_path / "o")], tmp_path / "c",
                     timeout=120)
    assert proc.returncode == 2 and "sensor.adc_bits = 1000" in proc.stderr and "1 to 24" in proc.stderr
    assert not (tmp_path / "c" / "tasks").exists()


@pytest.fixture
def task_env(tmp_path, monkeypatch):
    from benchmark.runner import tasks
    from benchmark.runner.config import RunConfig
    from benchmark.store.profiles import get_profile
    cfg = RunConfig(lenses=["l"], attacks=None, scenes="synthetic", profile=get_profile("smoke"), seeds=[0],
                    cache_dir=tmp_path)
    return tasks, cfg, monkeypatch


def test_a_lens_task_that_raises_is_a_failed_row_and_leaves_no_staging(task_env, tmp_path):
    tasks, cfg, monkeypatch = task_env
    from benchmark.runner.planning import Task

    def overflow(task, cfg, staging):
        (staging / "half.png").write_bytes(b"\x89PNG")
        raise OverflowError("cannot convert float infinity to integer")

    monkeypatch.setitem(tasks._KINDS, "bound", overflow)
    result = tasks.execute(Task("bound", 0, "l"), cfg, tmp_path)
    (row,) = result.rows
    assert (row.kind, row.lens, row.status, row.error.stage) == ("bound", "l", "failed", "measure")
    assert "OverflowError: cannot convert float infinity" in row.error.message and "bound_s0_l" in row.error.message
    assert not list(tmp_path.glob(".*staging-*"))
    with pytest.raises(KeyboardInterrupt):  # the user's Ctrl-C still ends the run, leaving no staging
        monkeypatch.setitem(tasks._KINDS, "bound", lambda *a: (_ for _ in ()).throw(KeyboardInterrupt()))
        tasks.execute(Task("bound", 0, "l2"), cfg, tmp_path)
    assert not list(tmp_path.glob(".*staging-*"))


def test_a_truncated_task_picture_is_reported_and_its_task_recomputed(task_env, tmp_path, caplog):
    tasks, cfg, monkeypatch = task_env
    from benchmark.runner.planning import Task
    from benchmark.runner.pictures import copy_picture
    calls = []

    def draw(task, cfg, staging):
        calls.append(1)
        (staging / "samples_l_seed0.png").write_bytes(b"\x89PNG" + bytes(range(256)) * 4)
        return tasks.TaskResult(meta={"pictures": ["samples_l_seed0.png"]})

    monkeypatch.setitem(tasks._KINDS, "lens", draw)
    task = Task("lens", 0, "l")
    tasks.execute(task, cfg, tmp_path)
    picture = tmp_path / task.key / "samples_l_seed0.png"
    whole = picture.read_bytes()
    picture.write_bytes(whole[:100])
    assert not tasks.is_cached(tmp_path, task)
    with pytest.raises(RuntimeError, match="samples_l_seed0.png is missing or does not match its checksum"):
        copy_picture(picture, tmp_path / "out.png")  # never copied into a run folder
    assert not (tmp_path / "out.png").exists()
    tasks.execute(task, cfg, tmp_path)
    assert len(calls) == 2 and str(picture) in caplog.text
    assert picture.read_bytes() == whole and tasks.is_cached(tmp_path, task)


def test_a_chart_write_that_fails_leaves_no_partial_file(tmp_path, monkeypatch):
    from matplotlib.figure import Figure

    from benchmark.results.charts import new_figure, save_figure

    def full_disk(self, fname, **kwargs):  # the disk fills halfway through the PNG
        if hasattr(fname, "write"):
            fname.write(b"\x89PNG half")
        else:
            with open(fname, "wb") as f:
                f.write(b"\x89PNG half")
        raise OSError(28, "No space left on device")

    fig = new_figure()
    monkeypatch.setattr(Figure, "savefig", full_disk)
    with pytest.raises(OSError, match="No space left"):
        save_figure(fig, tmp_path / "chart.png")
    assert list(tmp_path.iterdir()) == []



def test_a_plugin_exiting_while_it_loads_is_a_load_failure(tmp_path):
    (tmp_path / "exits.py").write_text("raise SystemExit(3)\n")
    loaded, failures = attacks.load_all([f"{tmp_path / 'exits.py'}:Anything"])
    assert loaded == [] and [f.error for f in failures] == ["SystemExit: 3"]


# ---- each attacker's cache is its own ------------------------------------------------------------

def test_each_attacker_caches_in_its_own_folder_and_cannot_name_anothers(tmp_path):
    from benchmark.runner.isolation import own_context
    from benchmark.store.cache import ArtifactCache
    root = tmp_path / "attacks"
    shared = attacks.FitContext(cache_dir=root, artifacts=ArtifactCache(root))
    reader, restorer, odd = (own_context(shared, n) for n in ("learned-reader", "nafnet-known-pairs", "../up"))
    key = {"lens": "gp", "budget": 1}
    # Its own kind lands where a run kept it before attackers had folders (cached fits stay valid) ...
    assert reader.artifacts.path("learned-reader", key) == ArtifactCache(root).path("learned-reader", key)
    assert reader.cache_dir == root / "learned-reader"
    # ... and another attacker's kind resolves inside the caller's own folder, never the other's.
    assert restorer.artifacts.path("learned-reader", key).is_relative_to(root / "nafnet-known-pairs")
    assert odd.cache_dir.parent == root and ".." not in odd.cache_dir.name
    restorer.artifacts.save("learned-reader", key, b"not the reader's")
    assert reader.artifacts.load("learned-reader", key) is None


def test_an_attacker_that_rewrites_anothers_cached_fit_fails_and_the_fit_is_rebuilt(tmp_path, caplog):
    """The probe: a restorer's fit zeroes learned-reader's cached weights and rewrites their checksum.
    Its fit fails, naming the folder; the tampered file is removed (learned-reader fits again instead
    of loading it); an honest attacker's call, and new files of another run, pass."""
    import hashlib
    import logging
    from benchmark.runner.isolation import attempt, own_context
    from benchmark.store.cache import ArtifactCache
    root = tmp_path / "attacks"
    shared = attacks.FitContext(cache_dir=root, artifacts=ArtifactCache(root))
    reader = own_context(shared, "learned-reader")
    key = {"lens": "gp"}
    weights = reader.artifacts.save("learned-reader", key, b"trained weights")

    def tamper() -> None:
        weights.write_bytes(b"\0" * 15)
        weights.with_name(weights.name + ".sha256").write_text(hashlib.sha256(b"\0" * 15).hexdigest() + "\n")

    with caplog.at_level(logging.ERROR):
        result = attempt("tamper", "fit", tamper, cache_root=root)
    from benchmark.results.schema import RowError
    assert isinstance(result, RowError) and result.attacker == "tamper"
    assert result.stage == "fit" and "learned-reader" in result.message and "removed" in result.message
    assert any("learned-reader" in r.message for r in caplog.records if r.levelno == logging.ERROR)
    assert not weights.exists() and reader.artifacts.load("learned-reader", key) is None

    def honest() -> str:
        own_context(shared, "honest").artifacts.save("honest", key, b"mine")
        (root / "learned-reader" / "another-run.safetensors").write_bytes(b"new")  # a file that did not exist
        return "done"

    assert attempt("honest", "fit", honest, cache_root=root) == "done"


def test_a_plugin_call_that_writes_into_the_leaderboard_folder_fails(tmp_path):
    from benchmark.results.schema import RowError
    from benchmark.runner.isolation import CacheGuard
    board = tmp_path / "leaderboard"
    (board / "entries").mkdir(parents=True)
    (board / "entries" / "gp__quick__synthetic.json").write_text("{}")
    quiet = CacheGuard(tmp_path / "attacks", "honest", leaderboard=board)
    assert quiet.failure("honest", "read") is None
    for write in (lambda: (board / "entries" / "planted.json").write_text("{}"),
                  lambda: (board / "entries" / "gp__quick__synthetic.json").write_text('{"rows": []}')):
        guard = CacheGuard(tmp_path / "attacks", "planter", leaderboard=board)
        write()
        error = guard.failure("planter", "fit")
        assert isinstance(error, RowError) and "leaderboard folder" in error.message and "entries/" in error.message
