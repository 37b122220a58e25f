"""Consistency of measured readers with the ideal observer: no reader may beat the ceiling.

A reader's exact-plate accuracy in a width bin whose whole 95 % interval lies above the ceiling's
upper 95 % limit anywhere in that bin is a violation: under the model no attacker can do that, so
either the model (lens, sensor, plate renderer) and the simulation disagree, or the scoring is
wrong. Violations are returned, never dropped; the caller reports them loudly.

The same check against the marginalised (tighter) ceiling (`marginal.py`) says something else: a reader
above it but below the genie's knows what the nuisance prior says no attacker knows (the plate's exact
position, scale or exposure), or the scenes' nuisances are narrower than the prior. It is reported,
naming that ceiling (`Violation.ceiling`), and fails nothing: only the genie's ceiling is a proven bound.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from benchmark.results.observer.ceiling import CeilingCurve


@dataclass(frozen=True)
class BinAccuracy:
    """One reader's measured exact-plate accuracy in one plate-width bin [low_px, high_px).

    accuracy in [0, 1]; interval: its 95 % (Wilson) interval; n_plates: plates scored.
    """

    reader: str
    lens: str
    low_px: float
    high_px: float
    accuracy: float
    interval: tuple[float, float]
    n_plates: int


@dataclass(frozen=True)
class Violation:
    """A reader whose interval lies above a ceiling; `ceiling_high` is the ceiling's upper limit used,
    `ceiling` which ceiling: "genie" (the proven bound) or "marginal" (the tighter one)."""

    measured: BinAccuracy
    ceiling_high: float
    ceiling: str = "genie"

    def message(self) -> str:
        m = self.measured
        reads = (f"reader {m.reader!r} on lens {m.lens!r} reads {100 * m.accuracy:.1f} % "
                 f"(95 % interval {100 * m.interval[0]:.1f}-{100 * m.interval[1]:.1f} %, {m.n_plates} plates) of "
                 f"{m.low_px:g}-{m.high_px:g} px plates")
        if self.ceiling == "marginal":
            return (f"{ABOVE_TIGHTER}: {reads}, above the tighter ceiling {100 * self.ceiling_high:.1f} % (upper 95 % "
                    "limit; the ideal observer that does not know the plate's position, scale and exposure) but not "
                    "above the genie's: it knows what the prior says no attacker knows, or the scenes' nuisances "
                    "are narrower than the prior")
        return (f"CEILING VIOLATION: {reads}, above the ideal observer's ceiling "
                f"{100 * self.ceiling_high:.1f} % (genie, upper 95 % limit): a modelling or scoring error")


ABOVE_TIGHTER = "ABOVE THE TIGHTER CEILING"  # how a marginal-ceiling crossing's message starts


def ceiling_high_in_bin(curve: CeilingCurve, low_px: float, high_px: float) -> float | None:
    """Largest upper 95 % limit of the plate ceiling over [low_px, high_px] (linear between tabulated
    widths); None when the bin lies outside the tabulated widths (nothing to check against). For a
    marginalised curve (`width_high_px` set), the largest upper limit of its bins that overlap the bin."""
    if curve.width_high_px is not None:  # a marginalised curve: each width stands for its bin [w_k, high_k)
        overlapping = (curve.widths_px < high_px) & (curve.width_high_px > low_px)
        return float(curve.plate_interval[overlapping, 1].max()) if overlapping.any() else None
    widths = curve.widths_px.astype(float)
    high = curve.plate_interval[:, 1]
    lo, hi = max(low_px, widths[0]), min(high_px, widths[-1])
    if lo > hi:
        return None
    inside = high[(widths >= lo) & (widths <= hi)]
    ends = np.interp([lo, hi], widths, high)
    return float(np.max(np.concatenate([inside, ends])))


def check_consistency(measured: list[BinAccuracy], curves: dict[str, CeilingCurve]) -> list[Violation]:
    """The violations among `measured` against each lens's ceiling curve (`curves` by lens name).

    Bins of a lens without a curve, or outside its tabulated widths, are not checked. A curve of T
    frames checks readers that saw T frames; pass the T = 1 curve for single-image readers. Each
    violation names the curve's kind (`CeilingCurve.kind`).
    """
    violations = []
    for m in measured:
        if not 0.0 <= m.interval[0] <= m.accuracy <= m.interval[1] <= 1.0:
            raise ValueError(f"reader {m.reader!r} on {m.lens!r}: interval {m.interval} must hold the accuracy "
                             f"{m.accuracy} inside [0, 1]")
        curve = curves.get(m.lens)
        if curve is None:
            continue
        ceiling = ceiling_high_in_bin(curve, m.low_px, m.high_px)
        if ceiling is not None and m.interval[0] > ceiling:
            violations.append(Violation(m, ceiling, curve.kind))
    return violations
