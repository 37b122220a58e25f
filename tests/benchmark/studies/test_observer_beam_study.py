"""The beam study's paired comparison, and its published record against the reader's defaults."""

from __future__ import annotations

import json

import pytest

from attacks.readers.ideal_observer_reader import IdealObserverReader
from benchmark.results.stats import mcnemar_exact
from benchmark.studies.observer_beam_study import OUT_JSON, paired


def test_paired_counts_the_plates_each_setting_alone_read():
    case = {"settings": {"narrow": {"correct": [True, False, False, True, False, False]},
                         "wide": {"correct": [True, True, True, False, False, True]}}}
    result = paired(case, "wide", "narrow")
    assert (result["gained"], result["lost"]) == (3, 1)
    assert result["difference"] == pytest.approx(2 / 6, abs=1e-4)
    assert result["p_value"] == pytest.approx(mcnemar_exact(3, 1))
    assert result["interval"][0] < result["difference"] < result["interval"][1]


def test_the_record_backs_the_readers_default_search():
    """The reader's default beam is the study's wider setting, and on the study's plates it read more."""
    record = json.loads(OUT_JSON.read_text(encoding="utf-8"))
    reader = IdealObserverReader()
    wide = record["pooled"]["a"]
    settings = record["cases"][0]["settings"][wide]
    assert (tuple(settings["beams"]), settings["max_sweeps"]) == (reader.beams, reader.max_sweeps)
    assert record["pooled"]["gained"] > record["pooled"]["lost"]
    assert record["pooled"]["p_value"] < 0.05
