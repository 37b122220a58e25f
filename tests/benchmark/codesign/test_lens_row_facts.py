"""The lens row says when a trained mask ended on a coefficient bound, the leaderboard shows it, and
a co-designed lens's training curves are copied into the run folder."""

import json
import types

from benchmark.codesign.codesigned_lenses import START_SPEC
from benchmark.codesign.schemes import SCHEMES
from benchmark.codesign.trainer import CoDesign
from benchmark.results.entries import make_entry
from benchmark.publish.tables import main_table
from benchmark.store.cache import seal
from benchmark.store.profiles import get_profile
from benchmark.runner.rows import training_facts
from benchmark.runner.pictures import training_curves
from benchmark.results.schema import Row
from lenses.spec import load_spec


def test_training_facts_from_the_record():
    assert training_facts({"bound_limited": True, "bound_limited_terms": ["Z4", "Z6"]}) == (
        {"bound_limited": 1.0}, {"bound_limited_terms": "Z4, Z6"})
    assert training_facts({"bound_limited": False, "bound_limited_terms": []}) == ({"bound_limited": 0.0}, {})
    assert training_facts(None) == ({}, {})
    assert training_facts({"name": "fixed-ideal"}) == ({}, {})  # a mask without bounds: nothing to say
    assert training_facts({"bound_limited": False, "config": {"version": 4}}) == (
        {"bound_limited": 0.0}, {"trainer_version": "4"})


def _lens_row(lens, seed, flag=None, terms=""):
    metrics = {"images_per_s": 10.0} | ({} if flag is None else {"bound_limited": flag})
    return Row(kind="lens", lens=lens, attack="lens", seed=seed, profile="quick", scenes="synthetic", metrics=metrics,
               notes={"bound_limited_terms": terms} if terms else {})


def _cell(entry):
    table = main_table([entry]).splitlines()
    head = [c.strip() for c in table[0].strip("|").split("|")]
    return [c.strip() for c in table[2].strip("|").split("|")][head.index("bound-limited")]


def test_leaderboard_marks_bound_limited_lenses():
    limited = make_entry("os-d-1000", [_lens_row("os-d-1000", 0, 1.0, "Z2, Z3"), _lens_row("os-d-1000", 1, 0.0),
                                       _lens_row("os-d-1000", 2, 1.0, "Z2, Z3")], {"name": "quick"}, None, None)
    assert _cell(limited) == "yes (2/3 seeds: Z2, Z3)"
    free = make_entry("gp", [_lens_row("gp", s, 0.0) for s in range(3)], {"name": "quick"}, None, None)
    assert _cell(free) == "no"
    fixed = make_entry("ideal", [_lens_row("ideal", 0)], {"name": "quick"}, None, None)
    assert _cell(fixed) == ""


def test_terms_on_a_bound_in_only_some_seeds_say_in_how_many():
    rows = [_lens_row("os-d-mtadam", 0, 1.0, "Z2 tilt x"), _lens_row("os-d-mtadam", 1, 1.0, "Z3 tilt y"),
            _lens_row("os-d-mtadam", 2, 0.0)]
    assert _cell(make_entry("os-d-mtadam", rows, {"name": "quick"}, None, None)) == (
        "yes (2/3 seeds: Z2 tilt x in 1, Z3 tilt y in 1)")
    rows = [_lens_row("os-d-1000", 0, 1.0, "Z2, Z3, Z4"), _lens_row("os-d-1000", 1, 1.0, "Z2, Z4")]
    assert _cell(make_entry("os-d-1000", rows, {"name": "quick"}, None, None)) == "yes (2/2 seeds: Z2, Z3 in 1, Z4)"


def test_training_curves_are_found_where_the_trainer_puts_them(tmp_path):
    run = CoDesign(load_spec(START_SPEC), SCHEMES["gp"], get_profile("smoke"), 0, "cpu", tmp_path / "cache")
    run.directory.mkdir(parents=True)
    (run.directory / "curves.png").write_bytes(b"\x89PNG fake")
    seal(run.directory / "curves.png")  # the trainer seals what it writes; an unsealed chart is not copied
    # The record as a loaded run carries it: through JSON (tuples become lists).
    record = json.loads(json.dumps({"name": run.name, "config": run.config}))
    lens = types.SimpleNamespace(name="gp", training_record=record)
    folder = tmp_path / "task"
    folder.mkdir()
    name = training_curves(lens, 0, tmp_path / "cache", folder)
    assert name == "curves_gp_seed0.png" and (folder / name).read_bytes() == b"\x89PNG fake"
    assert training_curves(types.SimpleNamespace(name="ideal", training_record=None), 0, tmp_path, folder) is None
