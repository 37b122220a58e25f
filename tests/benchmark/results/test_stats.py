"""benchmark.results.stats against scipy, textbook values, a coverage simulation and shrunk samples."""

from __future__ import annotations

import math

import numpy as np
import pytest
from scipy import stats as sps

from benchmark.results import stats

Z95 = 1.959963984540054


@pytest.mark.parametrize("successes,n", [(0, 10), (1, 10), (5, 10), (10, 10), (8, 41), (13, 41), (21, 41),
                                         (117, 200), (3, 1000)])
def test_wilson_and_exact_match_scipy(successes, n):
    ours_w = stats.wilson_interval(successes, n)
    ours_e = stats.exact_interval(successes, n)
    ref = sps.binomtest(successes, n)
    np.testing.assert_allclose(ours_w, tuple(ref.proportion_ci(method="wilson")), atol=1e-12)
    np.testing.assert_allclose(ours_e, tuple(ref.proportion_ci(method="exact")), atol=1e-9)


def test_intervals_hand_computed():
    # 5/10: centre 1/2, half-width z sqrt(1/40 + z^2/400) / (1 + z^2/10).
    half = Z95 * math.sqrt(0.025 + Z95**2 / 400) / (1 + Z95**2 / 10)
    np.testing.assert_allclose(stats.wilson_interval(5, 10), (0.5 - half, 0.5 + half), atol=1e-12)
    # 0/10: Wilson upper z^2 / (n + z^2); Clopper-Pearson upper 1 - (alpha/2)^(1/n).
    assert stats.wilson_interval(0, 10) == (0.0, pytest.approx(Z95**2 / (10 + Z95**2)))
    assert stats.exact_interval(0, 10) == (0.0, pytest.approx(1 - 0.025 ** (1 / 10)))
    assert stats.wilson_interval(0, 0) == (0.0, 1.0)


def test_bad_counts_are_named():
    with pytest.raises(ValueError, match="successes"):
        stats.wilson_interval(5, 3)
    with pytest.raises(ValueError, match="confidence"):
        stats.exact_interval(1, 3, confidence=95)


def test_bootstrap_mean_interval_matches_scipy():
    values = np.random.default_rng(3).gamma(2.0, 3.0, size=64)  # skewed, like per-scene PSNR gaps
    ours = stats.bootstrap_mean_interval(values, n_resamples=20_000, seed=1)
    ref = sps.bootstrap((values,), np.mean, n_resamples=20_000, method="percentile",
                        random_state=np.random.default_rng(2)).confidence_interval
    standard_error = values.std(ddof=1) / math.sqrt(values.size)
    assert abs(ours[0] - ref.low) < 0.05 * standard_error
    assert abs(ours[1] - ref.high) < 0.05 * standard_error
    assert stats.bootstrap_mean_interval(values, seed=1) == stats.bootstrap_mean_interval(values, seed=1)
    assert stats.bootstrap_mean_interval([4.0]) == (4.0, 4.0)
    with pytest.raises(ValueError, match="non-finite"):
        stats.bootstrap_mean_interval([1.0, float("nan")])


def test_paired_bootstrap_known_answers():
    base = np.random.default_rng(0).normal(20.0, 5.0, size=40)  # scenes differ a lot
    shifted = stats.paired_bootstrap(base + 1.0, base, n_resamples=2000)
    # A constant shift: the shared scene spread cancels exactly.
    assert shifted.difference == pytest.approx(1.0)
    assert (shifted.low, shifted.high) == (pytest.approx(1.0), pytest.approx(1.0))
    assert shifted.p_value == pytest.approx(2 / 2001)
    alternating = np.tile([1.0, -1.0], 20)
    null = stats.paired_bootstrap(base + alternating, base, n_resamples=2000)
    assert null.difference == pytest.approx(0.0) and null.p_value > 0.9 and null.low < 0 < null.high


def test_paired_bootstrap_agrees_with_paired_t_test_and_its_interval():
    rng = np.random.default_rng(5)
    for shift in (0.0, 0.1, 0.2, 0.3):
        b = rng.normal(25.0, 4.0, size=200)
        a = b + shift + rng.normal(0.0, 1.0, size=200)
        ours = stats.paired_bootstrap(a, b, n_resamples=20_000, seed=shift.as_integer_ratio()[1])
        t = sps.ttest_rel(a, b)
        assert abs(ours.p_value - t.pvalue) < 0.03 + 0.15 * t.pvalue, (shift, ours, t)
        low, high = t.confidence_interval()
        assert abs(ours.low - low) < 0.03 and abs(ours.high - high) < 0.03
        # Duality: the percentile interval excludes 0 exactly when p < 0.05.
        assert (ours.low > 0 or ours.high < 0) == (ours.p_value < 0.05)


def test_mcnemar_exact_hand_computed_and_scipy():
    assert stats.mcnemar_exact(0, 5) == pytest.approx(2 * 0.5**5)
    assert stats.mcnemar_exact(1, 9) == pytest.approx(2 * (1 + 10) / 2**10)  # P(X <= 1) = (C(10,0) + C(10,1)) / 2^10
    assert stats.mcnemar_exact(0, 0) == 1.0
    for b, c in [(3, 11), (20, 31), (7, 7)]:
        assert stats.mcnemar_exact(b, c) == pytest.approx(sps.binomtest(b, b + c, 0.5).pvalue)


def test_paired_table_counts_against_scipys_crosstab():
    rng = np.random.default_rng(3)
    a, b = rng.random(200) < 0.6, rng.random(200) < 0.3
    table = sps.contingency.crosstab(a, b).count  # rows: a False, True; columns: b False, True
    assert stats.paired_table(a, b).tolist() == [table[1, 1], table[1, 0], table[0, 1], table[0, 0]]
    assert stats.paired_table([True, False], [True, True]).tolist() == [1, 0, 1, 0]
    with pytest.raises(ValueError, match="one value per unit"):
        stats.paired_table([True], [True, False])


def test_paired_accuracy_difference_square_and_add_when_uncorrelated():
    # ad - bc = 0 (phi = 0): Newcombe's interval reduces to the square-and-add of two Wilsons.
    both, only_a, only_b, neither = 10, 10, 5, 5
    n = 30
    result = stats.paired_accuracy_difference(both, only_a, only_b, neither)
    p1, p2 = 20 / n, 15 / n
    l1, u1 = sps.binomtest(20, n).proportion_ci(method="wilson")
    l2, u2 = sps.binomtest(15, n).proportion_ci(method="wilson")
    assert result.difference == pytest.approx(5 / 30)
    assert result.low == pytest.approx(p1 - p2 - math.hypot(p1 - l1, u2 - p2))
    assert result.high == pytest.approx(p1 - p2 + math.hypot(p2 - l2, u1 - p1))
    assert result.p_value == pytest.approx(sps.binomtest(10, 15, 0.5).pvalue)
    assert result.n == n


@pytest.mark.slow
def test_paired_accuracy_interval_covers_the_true_difference():
    # Correlated reads (both readers find the same easy plates): acc 0.5 vs 0.4, 60 plates.
    probabilities = [0.3, 0.2, 0.1, 0.4]  # both, only A, only B, neither
    rng = np.random.default_rng(11)
    tables = rng.multinomial(60, probabilities, size=2000)
    covered = [(r.low <= 0.1 <= r.high) for r in (stats.paired_accuracy_difference(*t) for t in tables)]
    coverage = float(np.mean(covered))
    assert 0.93 <= coverage <= 0.985, coverage
    # Narrower than ignoring the pairing would allow: the shared easy plates cancel.
    paired = stats.paired_accuracy_difference(18, 12, 6, 24)
    unpaired_half = Z95 * math.sqrt(0.5 * 0.5 / 60 + 0.4 * 0.6 / 60)
    assert paired.high - paired.low < 2 * unpaired_half


def test_verdict_flips_to_cannot_tell_when_the_sample_shrinks():
    # 200 plates: A reads 120, B reads 80, on the same plates.
    big = stats.paired_accuracy_difference(60, 60, 20, 60)
    assert stats.verdict(big, "greater").label == stats.HOLDS
    assert stats.verdict(big, "less").label == stats.DOES_NOT_HOLD
    small = stats.paired_accuracy_difference(6, 6, 2, 6)  # the same rates on 20 plates
    assert small.difference == pytest.approx(big.difference)
    decided = stats.verdict(small, "greater")
    assert decided.label == stats.CANNOT_TELL
    assert "p = 0.289" in decided.text and "n = 20" in decided.text

    rng = np.random.default_rng(2)
    b = rng.normal(0.30, 0.08, size=64)          # per-scene mIoU of lens B
    a = b + 0.03 + rng.normal(0.0, 0.04, size=64)  # lens A keeps a little more
    assert stats.verdict(stats.paired_bootstrap(a, b), "greater").label == stats.HOLDS
    assert stats.verdict(stats.paired_bootstrap(a[:4], b[:4]), "greater").label == stats.CANNOT_TELL


def test_verdict_rejects_bad_direction():
    with pytest.raises(ValueError, match="direction"):
        stats.verdict(stats.paired_accuracy_difference(1, 1, 1, 1), "bigger")  # type: ignore[arg-type]


def _mean_of_strata(strata):
    return float(np.mean([x.mean() for x in strata]))


def test_stratified_paired_bootstrap_known_answers():
    rng = np.random.default_rng(4)
    b = [rng.normal(20.0, 5.0, size=n) for n in (30, 12, 50)]   # seeds of different sizes, scenes differ a lot
    shifted = stats.stratified_paired_bootstrap([x + 0.7 for x in b], b, _mean_of_strata, n_resamples=1000)
    # A constant difference: every resample gives it exactly (a degenerate interval).
    assert shifted.difference == pytest.approx(0.7)
    assert (shifted.low, shifted.high) == (pytest.approx(0.7), pytest.approx(0.7))
    assert shifted.p_value == pytest.approx(2 / 1001) and shifted.n == 92
    # Differences symmetric about zero within each seed: the interval covers 0, nothing to tell.
    null = stats.stratified_paired_bootstrap([x + np.tile([0.5, -0.5], len(x) // 2) for x in b], b,
                                             _mean_of_strata, n_resamples=2000)
    assert null.difference == pytest.approx(0.0, abs=1e-12) and null.low < 0 < null.high and null.p_value > 0.5
    assert stats.verdict(null, "greater").label == stats.CANNOT_TELL


def test_stratified_paired_bootstrap_matches_the_paired_bootstrap_on_one_stratum():
    rng = np.random.default_rng(8)
    b = rng.normal(25.0, 4.0, size=120)
    a = b + 0.3 + rng.normal(0.0, 1.0, size=120)
    ours = stats.stratified_paired_bootstrap([a], [b], _mean_of_strata, n_resamples=20_000, seed=1)
    reference = stats.paired_bootstrap(a, b, n_resamples=20_000, seed=2)
    assert ours.difference == pytest.approx(reference.difference)
    assert abs(ours.low - reference.low) < 0.03 and abs(ours.high - reference.high) < 0.03
    assert abs(ours.p_value - reference.p_value) < 0.01 + 0.2 * reference.p_value


def test_stratified_paired_bootstrap_never_claims_more_than_n_units_allow():
    # Two scenes that both favour A: every resample does, yet two units cannot show p < 0.5.
    result = stats.stratified_paired_bootstrap([np.array([21.0, 22.0])], [np.array([20.0, 20.5])], _mean_of_strata,
                                               n_resamples=500)
    assert result.low > 0 and result.p_value == pytest.approx(0.5)
    assert stats.verdict(result, "greater").label == stats.CANNOT_TELL


def test_stratified_paired_bootstrap_names_bad_input():
    with pytest.raises(ValueError, match="stratum 0"):
        stats.stratified_paired_bootstrap([np.zeros(3)], [np.zeros(4)], _mean_of_strata)
    with pytest.raises(ValueError, match="strata"):
        stats.stratified_paired_bootstrap([np.zeros(3)], [], _mean_of_strata)
