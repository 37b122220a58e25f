"""The consistency check: a reader that beats the ideal observer's ceiling must be reported."""

from __future__ import annotations

import numpy as np
import pytest
from scipy.stats import binomtest

import lenses
from common.plate_render import random_plate_text
from benchmark.results.observer.ceiling import Precision, ceiling_curve
from benchmark.results.observer.consistency import BinAccuracy, ceiling_high_in_bin, check_consistency


@pytest.fixture(scope="module")
def defocus_curve():
    coarse = Precision(interval_width=0.1, coarse_width=0.2, min_plates=4, batch=4, max_plates=8)
    return ceiling_curve(lenses.load("defocus"), (6, 12), frames=1, precision=coarse, pair=None)


def measured(reader: str, truths: list[str], reads: list[str], low: float, high: float) -> BinAccuracy:
    hits = sum(t == r for t, r in zip(truths, reads))
    ci = binomtest(hits, len(truths)).proportion_ci(0.95, method="wilson")
    return BinAccuracy(reader, "defocus", low, high, hits / len(truths), (ci.low, ci.high), len(truths))


def test_a_reader_that_copies_the_ground_truth_trips_the_check(defocus_curve):
    rng = np.random.default_rng(0)
    truths = [random_plate_text(rng) for _ in range(60)]
    cheat = measured("answer-key", truths, truths, 6, 12)
    honest = measured("guesser", truths, [random_plate_text(rng) for _ in truths], 6, 12)
    violations = check_consistency([cheat, honest], {"defocus": defocus_curve})
    assert [v.measured.reader for v in violations] == ["answer-key"]
    assert violations[0].ceiling_high < 0.9  # a 6-12 px plate through defocus is far from legible
    assert "CEILING VIOLATION" in violations[0].message() and "answer-key" in violations[0].message()


def test_bins_outside_the_curve_or_of_other_lenses_are_not_checked(defocus_curve):
    cheat = BinAccuracy("answer-key", "defocus", 200, 300, 1.0, (0.95, 1.0), 60)
    other = BinAccuracy("answer-key", "ideal", 6, 12, 1.0, (0.95, 1.0), 60)
    assert ceiling_high_in_bin(defocus_curve, 200, 300) is None
    assert check_consistency([cheat, other], {"defocus": defocus_curve}) == []


def test_the_bin_is_checked_against_its_most_generous_ceiling(defocus_curve):
    high = defocus_curve.plate_interval[:, 1]
    assert ceiling_high_in_bin(defocus_curve, 6, 12) == pytest.approx(high.max())
    assert ceiling_high_in_bin(defocus_curve, 0, 6) == pytest.approx(high[0])


def test_an_interval_that_does_not_hold_its_accuracy_is_refused(defocus_curve):
    with pytest.raises(ValueError, match="interval"):
        check_consistency([BinAccuracy("r", "defocus", 6, 12, 0.5, (0.6, 0.7), 10)], {"defocus": defocus_curve})
