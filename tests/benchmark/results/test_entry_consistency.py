"""An edited entry cannot change a published number: every way of editing one that the consistency checks
know (``entry_checks.check_units``) is refused on read, naming the file, the row and the field, and
``report`` renders nothing. Each case edits a copy of the published smoke entry of the ideal lens."""

from __future__ import annotations

import copy
import json
import re
import shutil

import pytest

from benchmark.publish import report as leaderboard_report
from benchmark.results.entries import LEADERBOARD, load_entries

NAME = "ideal__smoke__synthetic.json"
PUBLISHED = json.loads((LEADERBOARD / "entries" / NAME).read_text())


def plate_rows(d):
    return [i for i, r in enumerate(d["rows"]) if (r.get("units") or {}).get("unit") == "plate"]


def own_ids(d, i, rename):
    """Give row i a unit-ids list of its own, `rename`d."""
    row = d["rows"][i]
    ids = [rename(x) for x in d["unit_ids"][row["units"]["ids"]]]
    d["unit_ids"]["edited"] = ids
    row["units"]["ids"] = "edited"
    return d


def renamed_ids(d):
    return own_ids(d, plate_rows(d)[1], lambda x: x.replace("#0", "#9"))


def duplicated_row(d):
    d["rows"].append(copy.deepcopy(d["rows"][plate_rows(d)[0]]))
    return d


def other_seeds_ids(d):
    d["rows"][plate_rows(d)[0]]["units"]["prefix"] = "synthetic/val/1/"
    return d


def correct_out_of_range(d):
    d["rows"][plate_rows(d)[0]]["units"]["values"]["correct"][:2] = [2, -1]
    return d


def inflated_accuracy(d):
    d["rows"][plate_rows(d)[0]]["metrics"]["plate_acc"] = 1.0
    return d


def inflated_count(d):
    d["rows"][plate_rows(d)[0]]["metrics"]["n_plates"] = 1e9
    return d


def dropped_widths(d):
    del d["rows"][plate_rows(d)[1]]["units"]["values"]["width_px"]
    return d


def edited_psnr(d):
    i = next(i for i, r in enumerate(d["rows"]) if r["kind"] == "restorer")
    d["rows"][i]["metrics"]["psnr_db"] += 1.0
    return d


CASES = {
    "one chain's plate ids renamed": (renamed_ids, r"seed 0: rows\[\d+\] \(.*\) and rows\[\d+\] \(.*\) score different "
                                                   r"plates \(\d+ ids only in the first, \d+ only in the second\)"),
    "a (chain, seed) row twice": (duplicated_row, r"rows\[\d+\] \(ideal/.* seed 0\): a second reader row of '.*' at "
                                                  r"seed 0 \(the first is rows\[\d+\]\)"),
    "a row holding another seed's ids": (other_seeds_ids, r"rows\[\d+\] .*: units id 'synthetic/val/1/.*' is not of "
                                                          r"the row's seed 0"),
    "per-plate outcomes of 2 and -1": (correct_out_of_range, r"units.values.correct holds \[-1, 2\]; a plate's "
                                                             "outcome is 0 or 1"),
    "plate_acc its outcomes do not give": (inflated_accuracy, r"metrics.plate_acc = 1.0 but its units read \d+ of \d+"),
    "n_plates of a billion": (inflated_count, r"metrics.n_plates = 1000000000.0 but its units hold \d+ pooled plates"),
    "one row without widths": (dropped_widths, r"seed 0: rows\[\d+\] records plate widths and rows\[\d+\] does not"),
    "psnr_db its scenes do not give": (edited_psnr, r"metrics.psnr_db = .* but its \d+ scenes' units average"),
}


@pytest.fixture
def board(tmp_path):
    (tmp_path / "entries").mkdir()
    shutil.copy(LEADERBOARD / "entries" / NAME, tmp_path / "entries" / NAME)
    assert [e.lens for e in load_entries(tmp_path)] == ["ideal"]  # the published entry is consistent
    return tmp_path


@pytest.mark.parametrize("case", CASES)
def test_an_edited_entry_is_refused_naming_file_row_and_field(board, case):
    edit, message = CASES[case]
    path = board / "entries" / NAME
    path.write_text(json.dumps(edit(copy.deepcopy(PUBLISHED))))
    with pytest.raises(ValueError, match=re.escape(f"{path}: not a valid leaderboard entry: ") + ".*" + message):
        load_entries(board)
    with pytest.raises(ValueError, match=message):
        leaderboard_report.render(board)
    assert not (board / "README.md").exists() and not (board / "index.html").exists()


def test_every_published_entry_is_consistent():
    assert len(load_entries()) == len(list((LEADERBOARD / "entries").glob("*.json")))
