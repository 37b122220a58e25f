"""`python -m benchmark run --dry-run`: the task plan, cached or to compute, with measured costs; nothing computed."""

import os
import re
import subprocess
import sys

import pytest
import torch

import attacks
import benchmark
from benchmark.results.schema import read_results

pytestmark = pytest.mark.slow  # runs `python -m benchmark run --dry-run` and a run in subprocesses

# The smoke plan of one fixed lens and one restorer, in plan order (benchmark.runner.planning.plan).
TASKS = ["clean-utility_s0", "spectrum_s0", "sharp_s0", "lens_s0_ideal", "utility_s0_ideal", "bound_s0_ideal",
         "fit_s0_ideal_identity", "evaluate_s0_ideal"]
LINE = re.compile(r"^  (\S+)\s+(cached|compute)\s+(.*)$")


def dry_run(cache, cwd, *extra):
    proc = subprocess.run([sys.executable, "-m", "benchmark", "run", "--lens", "ideal", "--attack", "identity",
                           "--profile", "smoke", "--dry-run", *extra], capture_output=True, text=True, cwd=cwd,
                          env={**os.environ, "PLB_CACHE": str(cache)}, timeout=300)
    assert proc.returncode == 0, proc.stderr[-3000:]
    return {m[1]: (m[2], m[3]) for m in map(LINE.match, proc.stdout.splitlines()) if m}


@pytest.fixture(scope="module")
def plans(tmp_path_factory):
    """Dry run, real run (API, same cache), dry run again; each dry run in its own empty folder."""
    root = tmp_path_factory.mktemp("dry")
    cache, cwd = root / "cache", root / "cwd"
    cwd.mkdir()
    before = dry_run(cache, cwd)
    created_before = sorted(p.name for p in root.rglob("*"))
    with pytest.MonkeyPatch.context() as mp:
        mp.setenv("PLB_CACHE", str(cache))
        results = benchmark.run(lenses=["ideal"], attacks=["identity"], profile="smoke", out=root / "out")
        other_seed = benchmark.plan(lenses=["ideal"], attacks=["identity"], profile="smoke", seeds=[1])
    after = dry_run(cache, cwd, "--out", str(root / "out2"))
    return {"before": before, "after": after, "created_before": created_before, "root": root, "cwd": cwd,
            "results": read_results(root / "out" / "results.json"), "other_seed": other_seed, "run": results}


def test_before_a_run_every_task_is_to_compute_at_unknown_cost(plans):
    before = plans["before"]
    assert list(before) == TASKS
    assert all(state == "compute" and cost.startswith("unknown") for state, cost in before.values())


def test_a_dry_run_creates_nothing(plans):
    assert plans["created_before"] == ["cwd"]  # no cache folder, no runs/<date> in the working folder
    assert not (plans["root"] / "out2").exists() and list(plans["cwd"].iterdir()) == []


def test_after_the_run_every_task_is_cached_with_the_time_it_took(plans):
    after = plans["after"]
    assert list(after) == TASKS and all(state == "cached" for state, _ in after.values())
    # A task's recorded time is its rows' wall time: the lens task made the lens row.
    (lens_row,) = [r for r in plans["results"].rows if r.kind == "lens"]
    assert after["lens_s0_ideal"][1] == f"{lens_row.provenance['wall_s']:.1f} s when computed"


def test_another_seed_is_estimated_from_the_measured_tasks(plans):
    tasks = plans["other_seed"].tasks
    assert [t.key for t in tasks] == [k.replace("_s0", "_s1") for k in TASKS]
    for task in tasks:
        measured = plans["after"][task.key.replace("_s1", "_s0")][1]
        assert not task.cached and task.estimate.n == 1
        assert measured == f"{task.estimate.seconds:.1f} s when computed"


def test_a_corrupt_result_is_planned_for_compute_and_left_for_the_run_to_report(plans, monkeypatch):
    monkeypatch.setenv("PLB_CACHE", str(plans["root"] / "cache"))
    plan = benchmark.plan(lenses=["ideal"], attacks=["identity"], profile="smoke")
    result = plan.directory / "bound_s0_ideal" / "result.json"
    result.write_bytes(result.read_bytes()[:-10])  # truncated
    states = {t.key: t.state for t in benchmark.plan(lenses=["ideal"], attacks=["identity"], profile="smoke").tasks}
    assert states == {k: "compute" if k == "bound_s0_ideal" else "cached" for k in TASKS}
    assert result.exists()  # a dry run removes nothing


class FailsToRestore(attacks.Restorer):
    """Raises in restore: its evaluate task stores a failed row."""

    name = "test-fails-to-restore"
    threat_model = attacks.ThreatModel.SENSOR_ACCESS

    def restore(self, sensor: torch.Tensor) -> torch.Tensor:
        raise RuntimeError("injected")


def test_a_result_with_failures_is_planned_for_compute(plans, monkeypatch):
    monkeypatch.setenv("PLB_CACHE", str(plans["root"] / "cache"))
    results = benchmark.run(lenses=["ideal"], attacks=[FailsToRestore], profile="smoke")
    assert [r.error.stage for r in results.failed] == ["restore"]
    states = {t.key: t.state for t in benchmark.plan(lenses=["ideal"], attacks=[FailsToRestore], profile="smoke").tasks}
    assert states.pop("evaluate_s0_ideal") == "compute"  # a later run recomputes a result with failures
    assert set(states.values()) == {"cached"}


def test_adding_a_lens_or_a_seed_keeps_the_tasks_already_computed(plans, monkeypatch):
    # The task folder is keyed by what the tasks share, not by the lens list or the seeds: after the run of
    # ideal, a run of defocus and ideal (in that order) and seeds 0 and 1 finds ideal's seed-0 tasks cached.
    monkeypatch.setenv("PLB_CACHE", str(plans["root"] / "cache"))
    wider = benchmark.plan(lenses=["defocus", "ideal"], attacks=["identity"], profile="smoke", seeds=[0, 1])
    alone = benchmark.plan(lenses=["ideal"], attacks=["identity"], profile="smoke", seeds=[0])
    cached = {t.key for t in wider.tasks if t.cached}
    # (the tests before this one may have spoilt a result on purpose: compare with the single-lens plan)
    assert cached == {t.key for t in alone.tasks if t.cached} and len(cached) >= len(TASKS) - 2
    other = benchmark.plan(lenses=["ideal"], attacks=["identity"], profile="smoke", seeds=[0], frames=7)
    assert wider.directory == alone.directory != other.directory  # what a task depends on still keys it
