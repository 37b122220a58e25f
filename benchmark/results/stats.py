"""Sampling uncertainty of the suite's numbers, and paired verdicts on its findings.

Pure functions of counts and per-scene values (numpy / scipy, no torch): the runner attaches
their intervals to rows and the leaderboard decides each finding with a paired comparison.

- A proportion (plate accuracy, detection rate): ``wilson_interval`` (score interval, good
  coverage even for a handful of plates) or ``exact_interval`` (Clopper-Pearson, never below
  the nominal coverage, wider).
- A mean over scenes (PSNR, SSIM, mIoU, CER): ``bootstrap_mean_interval``, the percentile
  interval of the mean over scenes resampled with replacement (scenes are the independent
  units; pixels and plates within a scene are not).
- Two attackers or lenses on the same scenes: ``paired_bootstrap`` resamples the scenes once
  for both, so the between-scene spread they share cancels in the difference;
  ``stratified_paired_bootstrap`` does the same for any statistic of the units (a pooled mIoU
  from per-scene counts, the strongest of several restorers' mean PSNR) with the units of each
  seed resampled within their seed.
- Two readers on the same plates: ``mcnemar_exact`` (only the discordant plates carry
  information on the difference) and ``paired_accuracy_difference`` (the difference in
  accuracy with Newcombe's interval for paired proportions).
- ``verdict`` turns a comparison into "holds", "does not hold" or "cannot tell at this sample
  size", with the p-value and interval it rests on.
"""

from __future__ import annotations

import dataclasses
import math
from collections.abc import Callable, Sequence
from typing import Literal

import numpy as np
from scipy import stats as sps

__all__ = [
    "CANNOT_TELL",
    "DOES_NOT_HOLD",
    "HOLDS",
    "Comparison",
    "Verdict",
    "bootstrap_mean_interval",
    "exact_interval",
    "mcnemar_exact",
    "paired_accuracy_difference",
    "paired_bootstrap",
    "paired_table",
    "stratified_bootstrap_mean_interval",
    "stratified_paired_bootstrap",
    "verdict",
    "wilson_interval",
]

HOLDS = "holds"
DOES_NOT_HOLD = "does not hold"
CANNOT_TELL = "cannot tell at this sample size"

Direction = Literal["greater", "less"]


@dataclasses.dataclass(frozen=True)
class Comparison:
    """A paired difference ``a - b`` with its interval and two-sided p-value.

    Attributes:
        difference: The observed difference of the two means (or accuracies), ``a - b``.
        low, high: The ``confidence`` interval of the difference.
        p_value: Two-sided p-value of "no difference", in (0, 1].
        method: How interval and p-value were obtained, e.g. "paired-bootstrap".
        n: Number of paired units (scenes or plates).
        confidence: Coverage of the interval, e.g. 0.95.
    """

    difference: float
    low: float
    high: float
    p_value: float
    method: str
    n: int
    confidence: float = 0.95


@dataclasses.dataclass(frozen=True)
class Verdict:
    """A finding's decision: ``label`` is one of HOLDS, DOES_NOT_HOLD, CANNOT_TELL; ``text``
    states the evidence (difference, interval, p-value, method, n)."""

    label: str
    text: str


def _check_confidence(confidence: float) -> None:
    if not 0.0 < confidence < 1.0:
        raise ValueError(f"confidence must lie in (0, 1), got {confidence!r}")


def _check_counts(successes: int, n: int) -> None:
    if isinstance(successes, bool) or isinstance(n, bool) or int(successes) != successes or int(n) != n:
        raise ValueError(f"successes and n must be whole counts, got successes={successes!r}, n={n!r}")
    if n < 0 or not 0 <= successes <= n:
        raise ValueError(f"need 0 <= successes <= n, got successes={successes}, n={n}")


def wilson_interval(successes: int, n: int, confidence: float = 0.95) -> tuple[float, float]:
    """Wilson score interval of a binomial proportion.

    Args:
        successes: Number of successes (e.g. plates read correctly), 0 <= successes <= n.
        n: Number of trials (e.g. readable plates).
        confidence: Coverage, in (0, 1).

    Returns:
        (low, high) within [0, 1]; (0, 1) when n is 0 (nothing was measured).
    """
    _check_counts(successes, n)
    _check_confidence(confidence)
    if n == 0:
        return 0.0, 1.0
    z = sps.norm.ppf(0.5 + confidence / 2.0)
    p = successes / n
    denominator = 1.0 + z * z / n
    centre = (p + z * z / (2.0 * n)) / denominator
    half = z * math.sqrt(p * (1.0 - p) / n + z * z / (4.0 * n * n)) / denominator
    # The closed form is exact at the ends; clip only float round-off.
    low = 0.0 if successes == 0 else max(0.0, centre - half)
    high = 1.0 if successes == n else min(1.0, centre + half)
    return low, high


def exact_interval(successes: int, n: int, confidence: float = 0.95) -> tuple[float, float]:
    """Clopper-Pearson ("exact") interval of a binomial proportion, from beta quantiles.

    Args and returns as ``wilson_interval``; the interval is never narrower than needed for
    ``confidence`` coverage at any true proportion (hence usually wider than Wilson's).
    """
    _check_counts(successes, n)
    _check_confidence(confidence)
    if n == 0:
        return 0.0, 1.0
    tail = (1.0 - confidence) / 2.0
    low = 0.0 if successes == 0 else float(sps.beta.ppf(tail, successes, n - successes + 1))
    high = 1.0 if successes == n else float(sps.beta.ppf(1.0 - tail, successes + 1, n - successes))
    return low, high


def _finite_1d(values: Sequence[float] | np.ndarray, name: str) -> np.ndarray:
    array = np.asarray(values, dtype=np.float64)
    if array.ndim != 1 or array.size == 0:
        raise ValueError(f"{name} must be a non-empty 1-D sequence of per-scene values, got shape {array.shape}")
    if not np.all(np.isfinite(array)):
        raise ValueError(f"{name} holds non-finite values; drop or fix them before computing an interval")
    return array


def _resampled_means(values: np.ndarray, n_resamples: int, seed: int) -> np.ndarray:
    """Means of ``n_resamples`` resamples (with replacement) of the rows of ``values`` (n, ...)."""
    if n_resamples < 1:
        raise ValueError(f"n_resamples must be >= 1, got {n_resamples}")
    rng = np.random.default_rng(seed)
    # In chunks so that 10^4 resamples of a few hundred scenes never build a huge index array.
    means = []
    chunk = max(1, 2_000_000 // max(1, values.shape[0]))
    for start in range(0, n_resamples, chunk):
        index = rng.integers(0, values.shape[0], size=(min(chunk, n_resamples - start), values.shape[0]))
        means.append(values[index].mean(axis=1))
    return np.concatenate(means)


def bootstrap_mean_interval(values: Sequence[float] | np.ndarray, confidence: float = 0.95,
                            n_resamples: int = 10_000, seed: int = 0) -> tuple[float, float]:
    """Percentile bootstrap interval of a mean over scenes.

    Args:
        values: One value per scene (e.g. PSNR in dB), shape (n,), finite.
        confidence: Coverage, in (0, 1).
        n_resamples: Bootstrap resamples of the scenes.
        seed: Seed of the resampling (the same seed gives the same interval).

    Returns:
        (low, high) in the units of ``values``; (v, v) for a single scene (no spread to see).
    """
    _check_confidence(confidence)
    array = _finite_1d(values, "values")
    means = _resampled_means(array, n_resamples, seed)
    tail = (1.0 - confidence) / 2.0
    low, high = np.quantile(means, [tail, 1.0 - tail])
    return float(low), float(high)


def stratified_bootstrap_mean_interval(strata: Sequence[Sequence[float] | np.ndarray], confidence: float = 0.95,
                                       n_resamples: int = 4000, seed: int = 0) -> tuple[float, float]:
    """Percentile bootstrap interval of the mean over strata (seeds) of each stratum's mean over scenes.

    Each resample draws every stratum's scenes with replacement, keeping its size (the seeds are
    fixed, the scenes are the sampling units), as ``stratified_paired_bootstrap`` does for a difference.

    Args:
        strata: Per stratum one finite value per scene, shape (n_s,) with n_s >= 1.
        confidence, n_resamples, seed: As ``bootstrap_mean_interval``.

    Returns:
        (low, high) in the units of the values.
    """
    _check_confidence(confidence)
    if not strata:
        raise ValueError("stratified_bootstrap_mean_interval needs at least one stratum")
    arrays = [_finite_1d(s, f"stratum {i}") for i, s in enumerate(strata)]
    means = np.mean([_resampled_means(a, n_resamples, seed + i) for i, a in enumerate(arrays)], axis=0)
    tail = (1.0 - confidence) / 2.0
    low, high = np.quantile(means, [tail, 1.0 - tail])
    return float(low), float(high)


def paired_bootstrap(a: Sequence[float] | np.ndarray, b: Sequence[float] | np.ndarray,
                     confidence: float = 0.95, n_resamples: int = 10_000, seed: int = 0) -> Comparison:
    """Paired bootstrap of the difference of two means measured on the same scenes.

    The scenes are resampled once for both (the per-scene differences ``a - b`` are
    bootstrapped), so scene difficulty, which both share, cancels.

    Args:
        a, b: One value per scene for each side, shape (n,) each, scene i the same in both.
        confidence, n_resamples, seed: As ``bootstrap_mean_interval``.

    Returns:
        ``Comparison`` of ``mean(a) - mean(b)`` with its percentile interval and the two-sided
        p-value ``2 min(P*(d <= 0), P*(d >= 0))`` over the resampled mean differences ``d``
        (with the add-one correction, so never 0): the test dual to the percentile interval,
        which excludes 0 at level ``1 - confidence`` exactly when p is below that level.
    """
    _check_confidence(confidence)
    first, second = _finite_1d(a, "a"), _finite_1d(b, "b")
    if first.shape != second.shape:
        raise ValueError(f"a and b must hold one value per shared scene, got {first.size} and {second.size} values")
    differences = first - second
    means = _resampled_means(differences, n_resamples, seed)
    tail = (1.0 - confidence) / 2.0
    low, high = np.quantile(means, [tail, 1.0 - tail])
    below = (np.count_nonzero(means <= 0.0) + 1) / (n_resamples + 1)
    above = (np.count_nonzero(means >= 0.0) + 1) / (n_resamples + 1)
    return Comparison(float(differences.mean()), float(low), float(high), min(1.0, 2.0 * min(below, above)),
                      "paired-bootstrap", int(differences.size), confidence)


Statistic = Callable[[Sequence[np.ndarray]], float]


def stratified_paired_bootstrap(a: Sequence[np.ndarray], b: Sequence[np.ndarray], statistic: Statistic,
                                confidence: float = 0.95, n_resamples: int = 4000, seed: int = 0,
                                method: str = "paired-bootstrap") -> Comparison:
    """Paired bootstrap of ``statistic(a) - statistic(b)`` with units resampled within strata.

    Each stratum (one seed) holds the same units for both sides, in the same order: unit i of
    ``a[s]`` and of ``b[s]`` is one scene (or plate) measured under A and under B. A resample draws
    each stratum's units with replacement, keeping its size, and applies the same draw to both
    sides, so whatever the units share cancels in the difference.

    Args:
        a, b: Per stratum an array (n_s, ...) of per-unit values (n_s >= 1; ``a[s].shape[0] ==
            b[s].shape[0]``); the trailing shape may differ between strata only where
            ``statistic`` allows it.
        statistic: Maps the strata of one side (a list of arrays, one per stratum) to a float,
            e.g. the mean over strata of each stratum's pooled mIoU.
        confidence, n_resamples, seed: As ``paired_bootstrap``.
        method: Name recorded in the returned ``Comparison``.

    Returns:
        ``Comparison`` of the observed difference with the percentile interval and the two-sided
        bootstrap p-value of ``paired_bootstrap``, never below ``2 ** (1 - n)``: the smallest
        two-sided p-value an exact paired (sign-flip) test can reach with n units. On a handful
        of units the percentile bootstrap is overconfident (two scenes that both favour A put
        every resample on A's side), and no finding may rest on that. ``n`` is the number of
        paired units over all strata.
    """
    _check_confidence(confidence)
    if n_resamples < 1:
        raise ValueError(f"n_resamples must be >= 1, got {n_resamples}")
    if len(a) != len(b) or not a:
        raise ValueError(f"a and b need the same number (>= 1) of strata, got {len(a)} and {len(b)}")
    first = [np.asarray(x) for x in a]
    second = [np.asarray(x) for x in b]
    for s, (x, y) in enumerate(zip(first, second)):
        if x.shape[0] != y.shape[0] or x.shape[0] == 0:
            raise ValueError(f"stratum {s}: a and b must hold the same units (>= 1), got {x.shape[0]} and {y.shape[0]}")
    observed = float(statistic(first) - statistic(second))
    rng = np.random.default_rng(seed)
    differences = np.empty(n_resamples)
    for i in range(n_resamples):
        draws = [rng.integers(0, x.shape[0], size=x.shape[0]) for x in first]
        differences[i] = statistic([x[d] for x, d in zip(first, draws)]) - statistic([y[d] for y, d in zip(second, draws)])
    differences = differences[np.isfinite(differences)]
    if differences.size == 0:
        raise ValueError("the statistic is undefined on every resample; check the per-unit values")
    tail = (1.0 - confidence) / 2.0
    low, high = np.quantile(differences, [tail, 1.0 - tail])
    below = (np.count_nonzero(differences <= 0.0) + 1) / (differences.size + 1)
    above = (np.count_nonzero(differences >= 0.0) + 1) / (differences.size + 1)
    n = int(sum(x.shape[0] for x in first))
    p_value = min(1.0, max(2.0 * min(below, above), 2.0 ** (1 - n)))
    return Comparison(observed, float(low), float(high), p_value, method, n, confidence)


def mcnemar_exact(b: int, c: int) -> float:
    """Two-sided exact McNemar p-value for paired binary outcomes.

    Args:
        b: Units (plates) right under A and wrong under B.
        c: Units wrong under A and right under B.

    Returns:
        The exact binomial test of ``b`` successes in ``b + c`` trials at 1/2, two-sided
        (``scipy.stats.binomtest``); 1.0 when there is no discordant unit.
    """
    _check_counts(b, b + c)
    _check_counts(c, b + c)
    if b + c == 0:
        return 1.0
    return float(sps.binomtest(int(b), int(b + c), 0.5).pvalue)


def paired_table(a: Sequence[bool] | np.ndarray, b: Sequence[bool] | np.ndarray) -> np.ndarray:
    """The paired 2 x 2 table of two binary outcomes on the same units, as ``paired_accuracy_difference``
    takes it: (both right, right under A only, right under B only, neither), int counts."""
    ra, rb = np.asarray(a, dtype=bool), np.asarray(b, dtype=bool)
    if ra.shape != rb.shape:
        raise ValueError(f"paired outcomes need one value per unit under each; got shapes {ra.shape} and {rb.shape}")
    return np.array([np.sum(ra & rb), np.sum(ra & ~rb), np.sum(~ra & rb), np.sum(~ra & ~rb)], dtype=int)


def paired_accuracy_difference(both: int, only_a: int, only_b: int, neither: int,
                               confidence: float = 0.95) -> Comparison:
    """Difference of two accuracies on the same units, McNemar's exact test and its interval.

    Args:
        both: Units right under both A and B.
        only_a: Right under A only (McNemar's b).
        only_b: Right under B only (McNemar's c).
        neither: Wrong under both.
        confidence: Coverage of the interval, in (0, 1).

    Returns:
        ``Comparison`` of ``acc(A) - acc(B) = (only_a - only_b) / n``, its interval by
        Newcombe's hybrid score method for paired proportions (Newcombe 1998, Stat. Med. 17,
        2635, method 10: the two Wilson intervals combined with the continuity-corrected phi
        correlation of the paired table), and ``mcnemar_exact(only_a, only_b)``.
    """
    _check_confidence(confidence)
    cells = (both, only_a, only_b, neither)
    n = sum(cells)
    for cell in cells:
        _check_counts(cell, n)
    if n == 0:
        raise ValueError("paired_accuracy_difference needs at least one unit; all four counts are 0")
    p1, p2 = (both + only_a) / n, (both + only_b) / n
    l1, u1 = wilson_interval(both + only_a, n, confidence)
    l2, u2 = wilson_interval(both + only_b, n, confidence)
    margins = (both + only_a) * (only_b + neither) * (both + only_b) * (only_a + neither)
    cross = both * neither - only_a * only_b
    corrected = cross - n / 2.0 if cross > n / 2.0 else (cross if cross < 0 else 0.0)
    phi = corrected / math.sqrt(margins) if margins > 0 else 0.0
    difference = p1 - p2
    low = difference - math.sqrt(max(0.0, (p1 - l1) ** 2 - 2 * phi * (p1 - l1) * (u2 - p2) + (u2 - p2) ** 2))
    high = difference + math.sqrt(max(0.0, (p2 - l2) ** 2 - 2 * phi * (p2 - l2) * (u1 - p1) + (u1 - p1) ** 2))
    return Comparison(difference, max(-1.0, low), min(1.0, high), mcnemar_exact(only_a, only_b),
                      "mcnemar-exact+newcombe", n, confidence)


def verdict(comparison: Comparison, direction: Direction, alpha: float = 0.05) -> Verdict:
    """Decide a finding "A is greater (or less) than B" from a paired comparison of A - B.

    The decision is the two-sided test at level ``alpha``: p < alpha with the difference on
    the claimed side -> HOLDS; p < alpha on the other side -> DOES_NOT_HOLD (the opposite is
    shown); otherwise CANNOT_TELL (the sample cannot separate them, which is not evidence
    that they are equal).

    Args:
        comparison: The paired comparison of A - B (``paired_bootstrap`` or
            ``paired_accuracy_difference``).
        direction: "greater" (the finding claims A > B) or "less" (A < B).
        alpha: Significance level, in (0, 1).

    Returns:
        ``Verdict`` with the label and a text such as
        "holds: A - B = 0.120, 95 % CI [0.050, 0.190], p = 0.002 (paired-bootstrap, n = 64)".
    """
    if direction not in ("greater", "less"):
        raise ValueError(f"direction must be 'greater' or 'less', got {direction!r}")
    _check_confidence(1.0 - alpha)
    c = comparison
    if c.p_value < alpha and c.difference != 0.0:
        on_claimed_side = (c.difference > 0) == (direction == "greater")
        label = HOLDS if on_claimed_side else DOES_NOT_HOLD
    else:
        label = CANNOT_TELL
    p_text = "p < 0.001" if c.p_value < 0.001 else f"p = {c.p_value:.3f}"
    text = (f"{label}: A - B = {c.difference:.3g}, {100 * c.confidence:g} % CI [{c.low:.3g}, {c.high:.3g}], "
            f"{p_text} ({c.method}, n = {c.n})")
    return Verdict(label, text)
