"""Attackers: pluggable adversaries that try to recover private content from sensor images.

Restorers rebuild the sharp scene (``Restorer.restore``); readers pull licence-plate strings
out of an image (``Reader.read``). Attackers register in the entry-point group
``privacy_lens_bench.attacks`` (built-ins included) and are loaded lazily by name::

    import attacks
    a = attacks.load("wiener-known-psf")
    a.fit(attacks.FitContext(lens=lens))
    x_hat = a.restore(sensor)            # (B, 3, H, W) in [0, 1] -> same

Importing this package imports no attacker; ``attacks.available()`` lists them.

Importing it also sets the offline switches of ONNX Runtime and Hugging Face (``common.offline``)
before any attacker imports them.
"""

import common.offline  # noqa: F401

from attacks.base import (
    BUDGET_PROFILES,
    Attack,
    AttackBudget,
    FitContext,
    FitCurve,
    FitReport,
    LensLike,
    MissingRequirementError,
    PlateRead,
    ReadHints,
    Reader,
    Restorer,
    ThreatModel,
)
from attacks.registry import (
    DuplicatePluginError,
    PluginFailure,
    UnknownAttackError,
    available,
    load,
    load_all,
)

__all__ = [
    "BUDGET_PROFILES",
    "Attack",
    "AttackBudget",
    "FitCurve",
    "FitReport",
    "DuplicatePluginError",
    "FitContext",
    "LensLike",
    "MissingRequirementError",
    "PlateRead",
    "PluginFailure",
    "ReadHints",
    "Reader",
    "Restorer",
    "ThreatModel",
    "UnknownAttackError",
    "available",
    "load",
    "load_all",
]
