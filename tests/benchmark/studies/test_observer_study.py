"""The observer study merges into its stored record: only the lenses computed are replaced."""

from __future__ import annotations

import json
import shutil

import pytest

from benchmark.studies import observer_study as study
from benchmark.results.observer.ceiling import Precision, ceiling_curves

TINY = Precision(min_plates=2, batch=2, max_plates=2)


@pytest.fixture
def stored(tmp_path, monkeypatch):
    """A copy of the published study, and ceiling_curves made cheap (two plates, no letter pair)."""
    path = tmp_path / "ideal_observer.json"
    shutil.copy(study.REPO / "leaderboard" / "studies" / "ideal_observer.json", path)
    monkeypatch.setattr(study, "ceiling_curves",
                        lambda lens, widths, frames, **kw: ceiling_curves(lens, widths, frames, seed=kw["seed"],
                                                                          precision=TINY, pair=None,
                                                                          at_own_distance=kw["at_own_distance"]))
    return path


def test_computing_one_lens_keeps_every_other(stored):
    before = json.loads(stored.read_text())
    record = study.run_study(stored, None, names=("ideal",), widths_px=(4, 6), depth_lenses=(), precision=TINY,
                             note="test grid")
    after = json.loads(stored.read_text())
    assert after == json.loads(json.dumps(record)) and set(after["lenses"]) == set(before["lenses"])
    for name in set(before["lenses"]) - {"ideal"}:
        assert after["lenses"][name] == before["lenses"][name]
    ideal = after["lenses"]["ideal"]
    assert ideal["t1"]["curve"]["widths_px"] == [4, 6] and ideal["note"] == "test grid"
    assert ideal["seconds"] > 0 and len(ideal["load_average"]) == 2 and ideal["precision"]["max_plates"] == 2
    assert "at_own_distance" not in ideal  # not asked for: the old depth curve went with the old record
    assert after["not_computed"] == sorted(set(study.quick_lens_specs()) - set(after["lenses"]))


def test_depth_only_adds_the_depth_curve_and_keeps_the_flat_one(stored):
    before = json.loads(stored.read_text())
    name = next(iter(before["lenses"]))
    study.run_study(stored, None, names=(name,), widths_px=(4,), precision=TINY, depth_only=True)
    after = json.loads(stored.read_text())["lenses"][name]
    assert after["t1"] == before["lenses"][name]["t1"]
    deep = after["at_own_distance"]
    assert deep["t1"]["curve"]["widths_px"] == [4] and deep["t1"]["curve"]["object_distance_m"][0] > 10
    missing = next(n for n in study.quick_lens_specs() if n not in before["lenses"]) if before.get("not_computed") \
        else None
    if missing is not None:
        with pytest.raises(ValueError, match="depth_only needs the flat curve"):
            study.run_study(stored, None, names=(missing,), depth_only=True)


def test_an_unknown_lens_is_named():
    with pytest.raises(ValueError, match="not on the quick leaderboard"):
        study.run_study(names=("no-such-lens",))


def test_a_part_computed_apart_merges_by_lens(stored, tmp_path):
    part = tmp_path / "part.json"
    shutil.copy(stored, part)
    study.run_study(part, None, names=("ideal",), widths_px=(4,), depth_lenses=(), precision=TINY)
    before = json.loads(stored.read_text())
    merged = study.merge_study(stored, part, ("ideal",))
    assert merged == json.loads(stored.read_text())
    assert merged["lenses"]["ideal"] == json.loads(part.read_text())["lenses"]["ideal"]
    assert all(merged["lenses"][n] == before["lenses"][n] for n in before["lenses"] if n != "ideal")
    with pytest.raises(ValueError, match="has no record of"):
        study.merge_study(stored, part, ("no-such-lens",))


def test_reader_studies_read_apart_combine_and_are_checked_again(tmp_path):
    from benchmark.studies import reader_study
    specs = study.quick_lens_specs()
    paths = []
    for lens, correct in (("defocus", False), ("ideal", True)):
        plates = [{"lens": lens, "attack": "ideal-observer", "width_px": 40 + i, "correct": correct,
                   "truth": "AB123CD", "read": "AB123CD" if correct else "AB123CO"} for i in range(5)]
        part = {"profile": "quick", "scenes": "synthetic", "seed": 0, "n_plates_target": 5,
                "readers": ["ideal-observer"], "lens_specs": {lens: specs[lens]},
                "timing": {lens: {"ideal-observer": {"seconds": 1.0}}}, "plates": plates}
        paths.append(tmp_path / f"{lens}.json")
        paths[-1].write_text(json.dumps(part))
    out = reader_study.combine(paths, tmp_path / "readers.json")
    assert json.loads((tmp_path / "readers.json").read_text()) == json.loads(json.dumps(out))
    assert len(out["plates"]) == 10 and set(out["timing"]) == {"defocus", "ideal"}
    assert out["lenses"]["ideal"]["ideal-observer"]["bins"][0]["accuracy"] == 1.0
    assert out["lenses"]["defocus"]["ideal-observer"]["bins"][0]["n_plates"] == 5
    assert out["consistency"]["checked"] == ["defocus", "ideal"] and out["consistency"]["violations"] == []
    again = json.loads(paths[1].read_text())  # ideal read again (e.g. its spec changed): replaces, never doubles
    again["plates"] = again["plates"][:2]
    again["timing"] = {"ideal": {"ideal-observer": {"seconds": 2.0}}}
    paths.append(tmp_path / "ideal-again.json")
    paths[-1].write_text(json.dumps(again))
    out = reader_study.combine(paths, None)
    assert len(out["plates"]) == 7 and out["timing"]["ideal"]["ideal-observer"]["seconds"] == 2.0
    assert out["lenses"]["ideal"]["ideal-observer"]["bins"][0]["n_plates"] == 2
    paths.pop()
    other = json.loads(paths[0].read_text())
    other["seed"] = 1
    paths[0].write_text(json.dumps(other))
    with pytest.raises(ValueError, match="other settings"):
        reader_study.combine(paths, None)


def test_the_published_study_covers_every_quick_lens_and_no_reader_beats_it():
    """Every lens of the quick leaderboard has a ceiling computed for its very spec, W_5% separates
    ideal, defocus and os-d-1000, and the stored reader study re-checks clean against it."""
    from benchmark.results.observer import published
    from benchmark.studies import reader_study
    record = published.load_study()
    for name, spec in study.quick_lens_specs().items():
        assert published.study_record(record, name, spec) is not None, name
    assert record["not_computed"] == []
    w5 = {n: record["lenses"][n]["t1"]["w5_plate_px"] for n in ("ideal", "defocus", "os-d-1000")}
    assert len(set(w5.values())) == 3, w5
    readers = json.loads(reader_study.OUT_JSON.read_text())
    check = reader_study.summarise(readers["plates"], readers["lens_specs"], record)["consistency"]
    assert check["violations"] == [] and sorted(check["checked"]) == sorted(readers["lens_specs"])
