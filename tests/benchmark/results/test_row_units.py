"""Per-unit outcomes of rows (schema.Units): built from the measurement, exact, and round-tripped
through results.json and leaderboard entries."""

import json

import numpy as np
import pytest
import torch

from benchmark.results.entries import load_entries, make_entry, write_entry
from benchmark.results.plate_scoring import PlateOutcome, levenshtein
from benchmark.runner.rows import plate_units, scene_units, utility_units
from benchmark.scenes import load_scenes
from benchmark.results.schema import Results, Row, Units, dumps_compact, read_results, write_results
from benchmark.codesign.utility.scoring import confusion_matrix, scores

IDS = {"seed": 0, "profile": "smoke", "scenes": "synthetic"}


@pytest.fixture(scope="module")
def scenes():
    return load_scenes("synthetic", "val", 4, (64, 128), seed=0)


def test_miou_recomputed_from_stored_counts_equals_the_rows(scenes):
    rng = np.random.default_rng(0)
    target = torch.from_numpy(np.stack([s.labels for s in scenes]))
    # Predictions: the truth with a third of the pixels replaced by random classes.
    noise = torch.from_numpy(rng.integers(0, 19, size=target.shape)).to(target.dtype)
    keep = torch.from_numpy(rng.uniform(size=target.shape) < 0.67)
    pred = torch.where(keep & (target != 255), target, noise)
    per_scene = torch.stack([confusion_matrix(p[None], t[None]) for p, t in zip(pred, target)])
    units = Units.from_json(json.loads(json.dumps(utility_units(scenes, per_scene).to_json())))
    inter, union = np.array(units.values["intersection"]), np.array(units.values["union"])
    present = union.sum(0) > 0
    recomputed = float((inter.sum(0)[present] / union.sum(0)[present]).mean())
    assert recomputed == pytest.approx(scores(per_scene.sum(0))["miou"], abs=1e-12)
    # ... and for any subset of scenes (what a bootstrap resample needs).
    subset = [0, 2, 2]
    present = union[subset].sum(0) > 0
    assert float((inter[subset].sum(0)[present] / union[subset].sum(0)[present]).mean()) == pytest.approx(
        scores(per_scene[subset].sum(0))["miou"], abs=1e-12)
    assert units.names() == tuple(s.name for s in scenes) and units.prefix == "synthetic/val/0/"


def test_scene_ids_do_not_depend_on_anything_but_set_split_seed_index():
    a = load_scenes("synthetic", "val", 3, (64, 128), seed=1)
    b = load_scenes("synthetic", "val", 5, (64, 128), seed=1)
    assert [s.name for s in a] == [s.name for s in b[:3]]
    assert {s.name for s in a}.isdisjoint(s.name for s in load_scenes("synthetic", "val", 3, (64, 128), seed=2))


def test_scene_units_round_values_and_leave_out_non_finite_metrics(scenes):
    units = scene_units(scenes, {"psnr_db": [20.123456, 21.0, 22.5, 23.99999], "ssim": [0.5, float("inf"), 0.2, 0.1]})
    assert units.values == {"psnr_db": (20.1235, 21.0, 22.5, 24.0)}


def test_plate_units_number_the_plates_of_each_scene():
    outcomes = [PlateOutcome("s/a", "AB123", 40, "AB123", True, True, 0.0),
                PlateOutcome("s/a", "XY999", 40, "XY99", True, False, levenshtein("XY99", "XY999") / 5),
                PlateOutcome("s/b@x0y0p1", "QQ111", 50, "", False, False, 1.0)]
    units = plate_units(outcomes)
    assert units.names() == ("s/a#0", "s/a#1", "s/b@x0y0p1#0")
    assert units.values == {"correct": (1, 0, 0), "char_errors": (0, 1, 5), "width_px": (40, 40, 50)}


def test_units_reject_what_they_cannot_pair():
    with pytest.raises(ValueError, match="3 entries for 2 ids"):
        Units("scene", "", ("a", "b"), {"psnr_db": (1.0, 2.0, 3.0)})
    with pytest.raises(ValueError, match="unique"):
        Units("plate", "", ("a", "a"), {"correct": (1, 0)})
    with pytest.raises(ValueError, match="not one of"):
        Units("pixel", "", ("a",), {})
    with pytest.raises(ValueError, match="non-finite|nan"):
        Units("scene", "", ("a",), {"psnr_db": (float("nan"),)})


def _rows():
    names = [f"synthetic/val/0/{i:05d}" for i in range(6)]
    restorer = Row(kind="restorer", attack="wiener-known-psf", restorer="wiener-known-psf", lens="defocus",
                   metrics={"psnr_db": 21.0}, **IDS)
    restorer.set_units(Units.from_names("scene", names, {"psnr_db": [20.0, 21.5, 21.25, 20.0, 22.0, 21.0]}))
    plates = [f"{n}@x0y0p0#0" for n in names]
    readers = []
    for attack, restorer_name in (("lpdr", None), ("wiener-known-psf>lpdr", "wiener-known-psf")):
        row = Row(kind="reader" if restorer_name is None else "chain", attack=attack, restorer=restorer_name,
                  reader="lpdr", lens="defocus", metrics={"plate_acc": 0.5}, **IDS)
        row.set_units(Units.from_names("plate", plates, {"correct": [1, 0, 1, 0, 1, 0], "char_errors": [0, 2, 0, 1, 0, 3]}))
        readers.append(row)
    bound = Row(kind="bound", attack="bound", lens="defocus", metrics={"bound_width_eps_t1": 30.0}, **IDS)
    return [restorer, *readers, bound]


def test_units_round_trip_through_results_json(tmp_path):
    rows = _rows()
    path = write_results(tmp_path / "results.json", Results(rows))
    assert read_results(path).rows == rows
    text = path.read_text()
    assert '"correct": [1,0,1,0,1,0]' in text  # arrays of numbers stay on one line


def test_units_round_trip_through_an_entry_with_ids_stored_once(tmp_path):
    rows = _rows()
    (tmp_path / "entries").mkdir()
    path = write_entry(tmp_path / "entries" / "defocus__smoke__synthetic.json",
                       make_entry("defocus", rows, {"name": "smoke"}, None, None))
    stored = json.loads(path.read_text())
    assert len(stored["unit_ids"]) == 2  # the scenes, and the plates both reader rows share
    assert all(isinstance(r["units"]["ids"], str) for r in stored["rows"] if r["units"])
    (entry,) = load_entries(tmp_path)
    assert entry.rows == rows
    assert entry.units("wiener-known-psf>lpdr", 0) == rows[2].units and entry.units("bound", 0) is None


def test_entries_without_units_still_load(tmp_path):
    rows = _rows()
    for r in rows:
        r.units = None
    (tmp_path / "entries").mkdir()
    stored = make_entry("defocus", rows, {"name": "smoke"}, None, None).to_json()
    for r in stored["rows"]:
        del r["units"]  # as written before units existed
    assert "unit_ids" not in stored
    (tmp_path / "entries" / "defocus__smoke__synthetic.json").write_text(json.dumps(stored))
    (entry,) = load_entries(tmp_path)
    assert entry.rows == rows and entry.units("lpdr", 0) is None


def test_a_dangling_ids_key_is_named(tmp_path):
    stored = make_entry("defocus", _rows(), {"name": "smoke"}, None, None).to_json()
    stored["unit_ids"] = {}
    (tmp_path / "entries").mkdir()
    (tmp_path / "entries" / "x.json").write_text(json.dumps(stored))
    with pytest.raises(ValueError, match="unit ids"):
        load_entries(tmp_path)


def test_compact_json_leaves_strings_alone():
    obj = {"note": "sizes [1, 2]\n[3,\n 4]", "values": [1.5, -2e-05, 3], "nested": [[1, 2], [3, 4]]}
    text = dumps_compact(obj)
    assert json.loads(text) == obj
    assert '"values": [1.5,-2e-05,3]' in text and '[1,2]' in text
