"""The Python API (benchmark.api): the README example as written, attackers given as objects, its limits."""

import contextlib
import io
import math
import re
import subprocess
import sys
from pathlib import Path
from typing import ClassVar

import numpy as np
import pandas as pd
import pytest
import torch
from skimage.metrics import peak_signal_noise_ratio

import attacks
import benchmark
from benchmark import api
from benchmark.runner import attacker_objects
from benchmark.store.profiles import get_profile
from benchmark.scenes import load_scenes
from benchmark.results.schema import Row

ROOT = Path(__file__).resolve().parents[2]


class Passthrough(attacks.Restorer):
    """The sensor image unchanged: the very restoration of the registered `raw` reference."""

    name: ClassVar[str] = "test-passthrough"
    threat_model: ClassVar[attacks.ThreatModel] = attacks.ThreatModel.SENSOR_ACCESS

    def restore(self, sensor: torch.Tensor) -> torch.Tensor:
        return sensor.clone()


class Flat(attacks.Restorer):
    """A flat grey image at `level` in [0, 1], an option: two instances are two different attackers."""

    name: ClassVar[str] = "test-flat"
    threat_model: ClassVar[attacks.ThreatModel] = attacks.ThreatModel.SENSOR_ACCESS

    def __init__(self, level: float = 0.5) -> None:
        self.level = level

    def restore(self, sensor: torch.Tensor) -> torch.Tensor:
        return torch.full_like(sensor, self.level)

    def describe(self) -> dict:
        return {**super().describe(), "level": self.level}


@pytest.fixture(scope="module")
def cache(tmp_path_factory):
    """One PLB_CACHE for this module's runs (the clean net and plate spectrum are trained once)."""
    with pytest.MonkeyPatch.context() as mp:
        folder = tmp_path_factory.mktemp("cache")
        mp.setenv("PLB_CACHE", str(folder))
        yield folder


def readme_example() -> str:
    """The example of benchmark.api's docstring, dedented: the text the README shows."""
    doc = api.__doc__
    start = doc.index("::\n\n") + len("::\n\n")
    block = doc[start:doc.index("\n\n", start)]
    return "\n".join(line[4:] for line in block.splitlines()) + "\n"


@pytest.fixture(scope="module")
def example(cache):
    code = readme_example()
    assert len(code.strip().splitlines()) == 5
    namespace: dict = {}
    printed = io.StringIO()
    with contextlib.redirect_stdout(printed):
        exec(compile(code, "README example", "exec"), namespace)  # noqa: S102 - our own docstring
    return namespace, printed.getvalue()


def test_the_readme_shows_the_tested_example():
    """Once the README carries the API example, it must be the tested one, character for character."""
    readme = (ROOT / "README.md").read_text()
    shown = [b for b in re.findall(r"```python\n(.*?)```", readme, re.S) if "benchmark.run(" in b]
    for block in shown:
        assert block == readme_example()


@pytest.mark.slow
def test_example_table_has_one_row_per_lens_attack_seed(example):
    namespace, printed = example
    results, table = namespace["results"], namespace["table"]
    per_lens = {"lens", "utility", "bound", "wiener-known-psf", "lpdr-oracle", "wiener-known-psf>lpdr-oracle"}
    expected = {(lens, a, 0) for lens in ("gp", "ideal") for a in per_lens} | {("sharp", "utility", 0),
                                                                             ("sharp", "lpdr-oracle", 0)}
    keys = list(zip(table["lens"], table["attack"], table["seed"]))
    assert len(keys) == len(set(keys)) == len(expected) and set(keys) == expected
    assert table.shape[0] == len(results.rows) and (table["status"] == "ok").all()
    assert list(table.columns[:len(api.ID_COLUMNS)]) == list(api.ID_COLUMNS)
    for column in ("psnr_db", "psnr_db_ci_low", "psnr_db_ci_high", "plate_acc", "plate_acc_ci_low", "miou"):
        assert column in table.columns and pd.api.types.is_float_dtype(table[column])
    assert "wiener-known-psf>lpdr-oracle" in printed


@pytest.mark.slow
def test_example_table_is_the_rows_with_their_intervals(example):
    results, table = example[0]["results"], example[0]["table"]
    for row, (_, line) in zip(results.rows, table.iterrows()):
        assert (line["kind"], line["lens"], line["attack"], line["seed"]) == (row.kind, row.lens, row.attack, row.seed)
        for name, value in row.metrics.items():
            assert line[name] == value
            if name in row.intervals:
                low, high = row.intervals[name]
                assert (line[f"{name}_ci_low"], line[f"{name}_ci_high"]) == (low, high)
                assert low <= value <= high
        absent = [c for c in table.columns[len(api.ID_COLUMNS):] if c.split("_ci_")[0] not in row.metrics]
        assert line[absent].isna().all()


@pytest.mark.slow
def test_example_rows_validate_against_the_schema(example):
    results = example[0]["results"]
    for row in results.rows:
        assert isinstance(row, Row) and Row.from_json(row.to_json()) == row  # from_json validates
        assert row.profile == "smoke" and row.settings_hash in results.settings
    assert results.meta["profile"] == get_profile("smoke").to_dict() and results.out is None


@pytest.mark.slow
def test_results_read_back_give_the_same_table(example, tmp_path):
    results = example[0]["results"]
    again = benchmark.Results.read(results.write(tmp_path / "results.json"))
    pd.testing.assert_frame_equal(again.table(), results.table())


@pytest.fixture(scope="module")
def object_runs(cache):
    """The same lens attacked by a registered name, a class and an instance; then another instance."""
    first = benchmark.run(lenses=["ideal"], attacks=["raw", Passthrough, Flat(0.25)], profile="smoke")
    second = benchmark.run(lenses=["ideal"], attacks=[Flat(0.75)], profile="smoke")
    return first, second


def _restorer_row(results, name):
    (row,) = [r for r in results.rows if r.lens == "ideal" and r.restorer == name]
    return row


def flat_psnr_db(level: float) -> float:
    """Mean PSNR of a flat image at `level` against the smoke profile's sharp scenes, by scikit-image."""
    p = get_profile("smoke")
    scenes = load_scenes("synthetic", "val", p.n_val, p.image_size, 0)
    return float(np.mean([peak_signal_noise_ratio(s.image.astype(np.float64), np.full(s.image.shape, level),
                                                  data_range=1.0) for s in scenes]))


@pytest.mark.slow
def test_an_attacker_class_is_scored_like_the_registered_attacker_it_equals(object_runs):
    first, _ = object_runs
    ours, raw = _restorer_row(first, "test-passthrough"), _restorer_row(first, "raw")
    assert ours.ok and ours.kind == "restorer" and raw.kind == "reference"
    assert ours.metrics["psnr_db"] == raw.metrics["psnr_db"] and ours.metrics["ssim"] == raw.metrics["ssim"]
    assert first.settings[ours.settings_hash]["restorer"]["class"].endswith(":Passthrough")


@pytest.mark.slow
@pytest.mark.parametrize("run_index, level", [(0, 0.25), (1, 0.75)])
def test_an_instance_keeps_its_options(object_runs, run_index, level):
    results = object_runs[run_index]
    row = _restorer_row(results, "test-flat")
    assert results.settings[row.settings_hash]["restorer"]["level"] == level
    assert math.isclose(row.metrics["psnr_db"], flat_psnr_db(level), rel_tol=1e-9)


def test_attacker_objects_need_distinct_names(cache):
    with pytest.raises(attacks.DuplicatePluginError, match="'test-flat' is given twice"):
        benchmark.run(lenses=["ideal"], attacks=[Flat(0.1), Flat(0.2)], profile="smoke")


@pytest.mark.parametrize("bad, message", [(42, "neither a name"), (int, "neither a name"),
                                          (attacks.Restorer, "needs a class attribute `name`")])
def test_what_is_not_an_attacker_is_refused(cache, bad, message):
    with pytest.raises(TypeError, match=message):
        benchmark.run(lenses=["ideal"], attacks=[bad], profile="smoke")


def test_an_instance_cannot_travel_to_ray(cache):
    pytest.importorskip("ray")
    with pytest.raises(attacker_objects.AttackerTransportError, match="executor='local'"):
        benchmark.plan(lenses=["ideal"], attacks=[Flat(0.5)], profile="smoke", executor="ray")


def test_a_module_level_class_travels_by_module_path():
    ref, attacker = attacker_objects.reference(Passthrough, remote=True)
    assert ref.spec == f"{Passthrough.__module__}:Passthrough" and ref.name == attacker.name == "test-passthrough"
    assert type(attacker_objects.load(ref.spec)) is Passthrough


def test_a_class_defined_in_a_function_cannot_travel():
    class Local(Passthrough):
        name: ClassVar[str] = "test-local"

    with pytest.raises(attacker_objects.AttackerTransportError, match="inside a function"):
        attacker_objects.reference(Local, remote=True)
    ref, _ = attacker_objects.reference(Local, remote=False)  # in this process it is fine
    assert type(attacker_objects.load(ref.spec)) is Local


def test_different_options_key_different_task_results():
    a, _ = attacker_objects.reference(Flat(0.1), remote=False)
    b, _ = attacker_objects.reference(Flat(0.2), remote=False)
    assert a.name == b.name and a.identity != b.identity


@pytest.mark.parametrize("seeds", [[0, 0], [], ["0"], [True]])
def test_bad_seeds_are_named(cache, seeds):
    with pytest.raises(ValueError, match="seed"):
        benchmark.run(lenses=["ideal"], attacks=["identity"], profile="smoke", seeds=seeds)


def test_load_lens_and_lists():
    assert {"ideal", "gp"} <= set(benchmark.list_lenses()) and "wiener-known-psf" in benchmark.list_attacks()
    psf = benchmark.load_lens("ideal").psf()
    assert psf.shape[0] == 3 and torch.allclose(psf.sum(dim=(1, 2)), torch.ones(3, dtype=psf.dtype), atol=1e-6)
    with pytest.raises(LookupError, match="ideal"):
        benchmark.load_lens("idael")


@pytest.mark.slow
def test_import_benchmark_stays_cheap():
    code = "import sys, benchmark; assert 'torch' not in sys.modules and 'benchmark.api' not in sys.modules"
    subprocess.run([sys.executable, "-c", code], check=True, timeout=120)


def test_a_name_given_twice_runs_once_and_objects_keep_their_place():
    chosen = api.select_attackers(["identity", Flat(0.3), "lpdr-oracle", "identity", Passthrough], remote=False)
    assert [r.name for r in chosen.restorers] == ["identity", "test-flat", "test-passthrough"]
    assert [r.name for r in chosen.readers] == ["lpdr-oracle"] and chosen.failures == []


def test_a_class_whose_constructor_raises_is_a_load_failure_not_a_crash():
    class Broken(Passthrough):
        name: ClassVar[str] = "test-broken"

        def __init__(self) -> None:
            raise RuntimeError("no weights here")

    chosen = api.select_attackers([Broken, "identity"], remote=False)
    assert [r.name for r in chosen.restorers] == ["identity"]
    assert [(f.name, f.kind, f.error) for f in chosen.failures] == [("test-broken", "restorer",
                                                                     "RuntimeError: no weights here")]
