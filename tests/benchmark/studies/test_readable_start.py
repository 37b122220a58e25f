"""Where readable plates start: the shipped measurement follows from its counts, and a bad one is refused."""

from __future__ import annotations

import json

import numpy as np
import pytest

from benchmark.results import readable_start
from benchmark.results.plate_scoring import READABLE_MIN_WIDTH_PX, WIDTH_BINS_PX, readable, scored
from benchmark.scenes.records import Plate
from benchmark.studies.readable_start_study import best_bins, bin_counts


def test_start_is_the_smallest_bin_read_at_least_half():
    bins = [{"low_px": 8, "hits": 1, "n": 50}, {"low_px": 24, "hits": 25, "n": 50},
            {"low_px": 16, "hits": 24, "n": 50}, {"low_px": 32, "hits": 0, "n": 0}]
    assert readable_start.start_from(bins) == 24
    assert readable_start.start_from(bins, share=0.9) is None


def test_shipped_measurement_is_consistent_and_used():
    record = json.loads(readable_start.MEASUREMENT.read_text())
    assert record["start_px"] == READABLE_MIN_WIDTH_PX == readable_start.start_from(record["bins"])
    assert READABLE_MIN_WIDTH_PX in WIDTH_BINS_PX
    # Every bin from 8 to 64 px was measured on 50 sharp plates, and the best reader is named per bin.
    assert all(b["n"] == 50 for b in record["bins"] if b["low_px"] < 64)
    for b in record["bins"]:
        assert b["hits"] == max(r[WIDTH_BINS_PX.index(b["low_px"])]["hits"] for r in record["per_reader"].values())
    assert {"date", "git_commit", "torch", "load_average"} <= set(record["provenance"])


def test_bad_measurement_is_refused_with_the_remedy(tmp_path):
    path = tmp_path / "start.json"
    path.write_text(json.dumps({"start_px": 16, "bins": [{"low_px": 16, "hits": 1, "n": 50},
                                                         {"low_px": 24, "hits": 40, "n": 50}]}))
    with pytest.raises(RuntimeError, match="counts give 24 px.*python -m benchmark.studies.readable_start_study"):
        readable_start.measured_start(WIDTH_BINS_PX, path)
    path.write_text("{not json")
    with pytest.raises(RuntimeError, match="cannot be read"):
        readable_start.measured_start(WIDTH_BINS_PX, path)
    with pytest.warns(UserWarning, match="no readable-start measurement"):
        assert readable_start.measured_start(WIDTH_BINS_PX, tmp_path / "missing.json") == 32


def test_bin_counts_and_best_reader():
    widths = np.array([8, 9, 12, 30, 200])
    a = bin_counts(widths, np.array([1, 0, 0, 1, 1], dtype=bool), (8, 12, 24))
    b = bin_counts(widths, np.array([1, 1, 0, 0, 0], dtype=bool), (8, 12, 24))
    assert [(x["low_px"], x["hits"], x["n"]) for x in a] == [(8, 1, 2), (12, 0, 1), (24, 2, 2)]
    assert [x["reader"] for x in best_bins({"a": a, "b": b})] == ["b", "a", "a"]


def test_scored_and_readable_plates():
    def plate(width: int, visible: float = 1.0, mirrored: bool = False) -> Plate:
        return Plate("AB123CD", (10, 10, 10 + width, 14), 0, visible, mirrored)

    assert not scored(plate(7)) and scored(plate(8)) and not readable(plate(8))
    assert readable(plate(READABLE_MIN_WIDTH_PX)) and not readable(plate(READABLE_MIN_WIDTH_PX - 1))
    assert not scored(plate(40, visible=0.98)) and not scored(plate(40, mirrored=True))
