"""The Bayesian ideal observer of plate reading: the ceiling no attacker can beat, and its checks.

    curve = ceiling_curve(lens, widths_px=(16, 32, 64), frames=1)   # per-character and plate ceilings
    certified_width(curve)                                           # W_5%: largest width with ceiling <= 5 %
    check_consistency(readers, curve)                                # empirical readers above the ceiling
    marginal_ceiling_curves(lens, (16, 24), prior=NuisancePrior())    # the tighter ceiling: nuisances not told
"""

from benchmark.results.observer.ceiling import CeilingCurve, PlateModel, Precision, ceiling_curve, ceiling_curves, certified_width
from benchmark.results.observer.consistency import BinAccuracy, Violation, check_consistency
from benchmark.results.observer.marginal import convergence, marginal_ceiling_curves
from benchmark.results.observer.nuisance import NuisancePrior

__all__ = ["BinAccuracy", "CeilingCurve", "NuisancePrior", "PlateModel", "Precision", "Violation", "ceiling_curve",
           "ceiling_curves", "certified_width", "check_consistency", "convergence", "marginal_ceiling_curves"]
