"""The Bayesian ideal observer of plate reading: the ceiling no attacker can beat, and its checks.

    curve = ceiling_curve(lens, widths_px=(16, 32, 64), frames=1)   # per-character and plate ceilings
    certified_width(curve)                                           # W_5%: largest width with ceiling <= 5 %
    check_consistency(readers, curve)                                # empirical readers above the ceiling
"""

from benchmark.results.observer.ceiling import CeilingCurve, PlateModel, Precision, ceiling_curve, ceiling_curves, certified_width
from benchmark.results.observer.consistency import BinAccuracy, Violation, check_consistency

__all__ = ["BinAccuracy", "CeilingCurve", "PlateModel", "Precision", "Violation", "ceiling_curve", "ceiling_curves",
           "certified_width", "check_consistency"]
