"""A trained attacker is fitted once and shared by its chains, a second run loads it instead of refitting,
and a profiled run (benchmark/runner/diagnostics/profiling.py) says where its time went.

Two smoke runs on one cache; the second has another attacker set (hence its own task folder, every
task recomputed) and is profiled.
"""

from __future__ import annotations

import json

import pytest

import attacks.training.restorer_training
from attacks.readers.plates import memo
from benchmark.runner.diagnostics import profiling
from benchmark.runner import runner
from benchmark.store.profiles import get_profile
from benchmark.runner.config import RunConfig

pytestmark = pytest.mark.slow  # two in-process smoke runs (about 2 min)


@pytest.fixture(scope="module")
def two_runs(tmp_path_factory):
    cache = tmp_path_factory.mktemp("cache")
    out = tmp_path_factory.mktemp("out")
    trainings: list[int] = []
    real = attacks.training.restorer_training.train_restorer

    def counting(model, next_batch, steps, device, seed, checkpoint=None):
        trainings.append(steps)
        return real(model, next_batch, steps, device, seed, checkpoint)

    def cfg(attack_names):
        return RunConfig(lenses=["defocus"], attacks=attack_names, scenes="synthetic", profile=get_profile("smoke"),
                         seeds=[0], cache_dir=cache)

    with pytest.MonkeyPatch.context() as mp:
        mp.setattr(attacks.training.restorer_training, "train_restorer", counting)
        first = runner.run(cfg(["nafnet-known-pairs", "lpdr-oracle"]))
        trained_first = len(trainings)
        # From an empty read memory: an earlier test in this process may have read the same crops,
        # and remembered reads would skip the OCR stage the profile is checked for.
        with memo.fresh(), profiling.profiled(out, get_profile("smoke").n_val, trace_python=True) as profiler:
            second = runner.run(cfg(["nafnet-known-pairs", "lpdr-oracle", "identity"]))
    return first, second, trained_first, len(trainings) - trained_first, out, profiler


def _rows(result, attack):
    return [r for r in result.rows if r.attack == attack and r.ok]


def test_one_fit_serves_the_restorer_and_its_chain(two_runs):
    first, _, trained_first, _, _, _ = two_runs
    assert trained_first == 1
    assert _rows(first, "nafnet-known-pairs") and _rows(first, "nafnet-known-pairs>lpdr-oracle")


def test_a_second_run_loads_the_fit_instead_of_refitting(two_runs):
    first, second, _, trained_second, _, _ = two_runs
    assert trained_second == 0
    fitted = [r.metrics["psnr_db"] for r in _rows(first, "nafnet-known-pairs")]
    loaded = [r.metrics["psnr_db"] for r in _rows(second, "nafnet-known-pairs")]
    # The same weights restore the same images; the runs' float reductions may differ in the last
    # bits (seen once in a full-suite run: 18.451579927 against 18.451579932 dB).
    assert loaded == pytest.approx(fitted, rel=1e-7, abs=0)


def test_the_profile_lists_every_computed_task_with_its_stages(two_runs):
    _, second, _, _, out, profiler = two_runs
    profile = json.loads((out / "profile.json").read_text())
    kinds = {t["kind"] for t in profile["tasks"]}
    assert {"lens", "fit", "evaluate", "utility", "bound", "sharp"} <= kinds
    assert abs(sum(t["share"] for t in profile["tasks"]) - 1) < 1e-9
    assert profile["profiled_s"] <= profile["wall_s"]
    evaluate = next(t for t in profile["tasks"] if t["kind"] == "evaluate")
    stages = {s["stage"]: s for s in evaluate["stages"]}
    # Restored by two restorers and read on the sensor image and two restorations: 3 read passes.
    assert stages["restore"]["calls"] == 2 and stages["read plates"]["calls"] == 3
    assert 0 < stages["read: OCR"]["seconds"] <= stages["read plates"]["seconds"] <= evaluate["seconds"]
    assert evaluate["images_per_s"] == pytest.approx(get_profile("smoke").n_val / evaluate["seconds"])
    fit = next(t for t in profile["tasks"] if t["kind"] == "fit" and t["label"] == "fit nafnet-known-pairs")
    assert "restorer fit" not in {s["stage"] for s in fit["stages"]}  # loaded, not trained
    assert evaluate["top_functions"] and all(f["cumulative_s"] < evaluate["seconds"] for f in evaluate["top_functions"])
    assert evaluate["rss_peak_mib"] > 0 and evaluate["python_peak_mib"] > 0
    sampled = evaluate["rss_sampled"]
    if sampled["peak_mib"] is not None:  # Linux: the sampled peak, a lower bound on the high-water mark
        assert sampled["samples"] > 0 and sampled["peak_mib"] <= evaluate["rss_peak_mib"] + 1
        assert all(s["rss_peak_mib"] <= sampled["peak_mib"] for s in evaluate["stages"] if s["rss_peak_mib"])
        assert stages["read plates"]["rss_peak_mib"] is not None
        assert "Sampled resident peak" in (out / "profile.md").read_text()
    markdown = (out / "profile.md").read_text()
    assert profiling.cost_table(profile) in markdown and "| evaluate | defocus | 1 |" in markdown
    assert profiler.tasks == profile["tasks"]
    # A CPU run's stage seconds are what they say; a GPU run's are host time, and the page says so.
    assert profile["device"] == "cpu" and profiling.ASYNC_NOTE not in markdown
    assert profiling.ASYNC_NOTE in profiling.render_markdown({**profile, "device": "cuda:0"})


def test_profiling_refuses_ray_and_does_nothing_when_off(tmp_path):
    with pytest.raises(ValueError, match="--executor local"):
        with profiling.profiled(tmp_path, 4, executor="ray"):
            pass
    assert not (tmp_path / "profile.json").exists()
    with profiling.task_scope(object()):  # no active profiler: a no-op whatever the task
        pass


def test_python_allocations_are_traced_only_when_asked():
    """tracemalloc slows Python-heavy tasks by about a third: off unless asked, and the report says so."""
    import tracemalloc

    from benchmark.runner.planning import Task

    seen = {}
    for trace in (False, True):
        profiler = profiling.RunProfiler(4, trace_python=trace)
        with profiler.task(Task(kind="bound", seed=0, lens="ideal")):
            seen[trace] = tracemalloc.is_tracing()
            _ = [bytearray(1 << 20) for _ in range(8)]  # 8 MiB of Python allocations
        assert not tracemalloc.is_tracing()
        record = profiler.tasks[0]
        if trace:
            assert record["python_peak_mib"] >= 8
        else:
            assert record["python_peak_mib"] is None
            assert "not traced (--profile-python-memory)" in profiling.render_markdown(profiler.summary())
    assert seen == {False: False, True: True}
