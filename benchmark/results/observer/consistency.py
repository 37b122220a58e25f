"""Consistency of measured readers with the ideal observer: no reader may beat the ceiling.

A reader's exact-plate accuracy in a width bin whose whole 95 % interval lies above the ceiling's
upper 95 % limit anywhere in that bin is a violation: under the model no attacker can do that, so
either the model (lens, sensor, plate renderer) and the simulation disagree, or the scoring is
wrong. Violations are returned, never dropped; the caller reports them loudly.
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
    """A reader whose interval lies above the ceiling; `ceiling_high` is the ceiling's upper limit used."""

    measured: BinAccuracy
    ceiling_high: float

    def message(self) -> str:
        m = self.measured
        return (f"CEILING VIOLATION: reader {m.reader!r} on lens {m.lens!r} reads {100 * m.accuracy:.1f} % "
                f"(95 % interval {100 * m.interval[0]:.1f}-{100 * m.interval[1]:.1f} %, {m.n_plates} plates) of "
                f"{m.low_px:g}-{m.high_px:g} px plates, above the ideal observer's ceiling "
                f"{100 * self.ceiling_high:.1f} % (upper 95 % limit): a modelling or scoring error")


def ceiling_high_in_bin(curve: CeilingCurve, low_px: float, high_px: float) -> float | None:
    """Largest upper 95 % limit of the plate ceiling over [low_px, high_px] (linear between tabulated
    widths); None when the bin lies outside the tabulated widths (nothing to check against)."""
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
    frames checks readers that saw T frames; pass the T = 1 curve for single-image readers.
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
            violations.append(Violation(m, ceiling))
    return violations
