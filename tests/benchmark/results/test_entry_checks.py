"""A malformed leaderboard entry is refused with its file, its field and what would be valid, instead of
rendering wrong or failing inside the renderer."""

from __future__ import annotations

import json
import re

import pytest

from benchmark.publish import leaderboard
from benchmark.publish import report as leaderboard_report
from benchmark.results.entries import load_entries, make_entry, write_entry
from benchmark.results.entry_checks import metric_range
from benchmark.results.schema import Row
from benchmark.store.profiles import get_profile

PROFILE = get_profile("smoke").to_dict()


def _rows(lens: str = "gp", miou: float = 0.3) -> list[Row]:
    ids = {"lens": lens, "seed": 0, "profile": "smoke", "scenes": "synthetic"}
    return [Row(kind="utility", attack="utility", metrics={"miou": miou, "iou_road": 0.5}, **ids),
            Row(kind="restorer", attack="identity", restorer="identity", metrics={"psnr_db": 20.0, "ssim": 0.5}, **ids)]


@pytest.fixture
def board(tmp_path):
    """A leaderboard with two valid entries: `gp` (the one the tests break) and `ideal`."""
    for lens in ("gp", "ideal"):
        write_entry(tmp_path / "entries" / f"{lens}__smoke__synthetic.json", make_entry(lens, _rows(lens), PROFILE,
                                                                                          None, None))
    assert [e.lens for e in load_entries(tmp_path)] == ["gp", "ideal"]
    return tmp_path


def _break(board, edit) -> None:
    path = board / "entries" / "gp__smoke__synthetic.json"
    data = json.loads(path.read_text())
    path.write_text(json.dumps(edit(data)))


def _set(data, keys, value):
    target = data
    for key in keys[:-1]:
        target = target[key]
    target[keys[-1]] = value
    return data


CASES = {
    "seeds as a string": (lambda d: _set(d, ["seeds"], "zero"),
                          "field 'seeds' must be a list of non-negative integers, got 'zero'"),
    "a list instead of an entry": (lambda d: [d], "an entry is a JSON object with the fields .*, got a JSON list"),
    "mIoU above 1": (lambda d: _set(d, ["rows", 0, "metrics", "miou"], 7.5),
                     r"rows\[0\] \(gp/utility seed 0\): metrics.miou = 7.5 is outside \[0.0, 1.0\]"),
    "a class IoU below 0": (lambda d: _set(d, ["rows", 0, "metrics", "iou_road"], -0.1),
                            r"rows\[0\] .*metrics.iou_road = -0.1 is outside \[0.0, 1.0\] \(iou_road is a fraction\)"),
    "SSIM above 1": (lambda d: _set(d, ["rows", 1, "metrics", "ssim"], 2.0), r"rows\[1\] .*metrics.ssim = 2.0"),
    "metrics as a string": (lambda d: _set(d, ["rows", 1, "metrics"], "fast"), r"rows\[1\]: "),
    "a metric as a string": (lambda d: _set(d, ["rows", 1, "metrics", "psnr_db"], "20"),
                             r"rows\[1\]: metric 'psnr_db' must be a number, got '20'"),
    "a row of another lens": (lambda d: _set(d, ["rows", 1, "lens"], "os"),
                              r"rows\[1\] .*lens 'os' is not the entry's 'gp'"),
    "a row of a seed the entry does not list": (lambda d: _set(d, ["rows", 1, "seed"], 3),
                                                r"rows\[1\] \(gp/identity seed 3\): seed 3 is not one of the entry's seeds \[0\]"),
    "a row that is not an object": (lambda d: _set(d, ["rows", 1], "identity"),
                                    "field 'rows' must be a list of row objects"),
    "lens as a number": (lambda d: _set(d, ["lens"], 5), "field 'lens' must be a non-empty string, got 5"),
    "a missing field": (lambda d: {k: v for k, v in d.items() if k != "profile_values"},
                        r"the entry lacks field\(s\) \['profile_values'\]"),
    "an unknown field": (lambda d: _set(d, ["score"], 1), r"the entry has unknown field\(s\) \['score'\]; valid: \['coefficients_um'"),
    "coefficients as text": (lambda d: _set(d, ["coefficients_um"], "0.1"),
                             "field 'coefficients_um' must be null or a list of finite numbers"),
}


@pytest.mark.parametrize("case", CASES)
def test_a_malformed_entry_names_its_file_and_field(board, case):
    edit, message = CASES[case]
    _break(board, edit)
    path = re.escape(str(board / "entries" / "gp__smoke__synthetic.json"))
    with pytest.raises(ValueError, match=f"{path}: not a valid leaderboard entry: {message}"):
        load_entries(board)
    # Rendering stops on the same message before writing anything: no page shows the broken entry.
    with pytest.raises(ValueError, match=message):
        leaderboard_report.render(board)
    assert not (board / "README.md").exists() and not (board / "index.html").exists()


def test_publishing_into_a_malformed_entry_names_it_and_loses_nothing(board):
    _break(board, lambda d: _set(d, ["seeds"], "zero"))
    broken = (board / "entries" / "gp__smoke__synthetic.json").read_bytes()
    with pytest.raises(ValueError, match=r"gp__smoke__synthetic.json: not a valid leaderboard entry: field 'seeds'"):
        leaderboard.publish(_rows("gp"), PROFILE, {}, board)
    assert (board / "entries" / "gp__smoke__synthetic.json").read_bytes() == broken  # left for the user to fix


def test_a_run_with_an_out_of_range_metric_is_not_published(board):
    before = {p.name: p.read_bytes() for p in (board / "entries").iterdir()}
    with pytest.raises(ValueError, match=r"refusing to write an invalid leaderboard entry: .*metrics.miou = 7.5"):
        leaderboard.publish(_rows("gp", miou=7.5), PROFILE, {}, board)
    assert {p.name: p.read_bytes() for p in (board / "entries").iterdir()} == before


def test_the_published_leaderboard_passes_the_checks():
    entries = load_entries()  # the repository's leaderboard
    assert entries and all(isinstance(s, int) for e in entries for s in e.seeds)


def test_metric_ranges():
    assert metric_range("miou")[:2] == (0.0, 1.0) and metric_range("iou_traffic light")[:2] == (0.0, 1.0)
    assert metric_range("ssim")[:2] == (-1.0, 1.0) and metric_range("n_plates")[0] == 0.0
    assert metric_range("psnr_db") is None and metric_range("bound_bits_w16_t1") is None
