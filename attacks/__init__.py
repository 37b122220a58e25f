"""Attackers: pluggable adversaries that try to recover private content from sensor images.

Restorers rebuild the sharp scene (``Restorer.restore``); readers pull licence-plate strings
out of an image (``Reader.read``). Attackers register in the entry-point group
``privacy_lens_bench.attacks`` (built-ins included) and are loaded lazily by name::

    import attacks
    a = attacks.load("wiener-known-psf")
    a.fit(attacks.FitContext(lens=lens))
    x_hat = a.restore(sensor)            # (B, 3, H, W) in [0, 1] -> same

Importing this package imports no attacker; ``attacks.available()`` lists them.

Importing it also turns ONNX Runtime's telemetry off (``ORT_DISABLE_TELEMETRY=1`` unless the
environment already names a value): since 1.29 the official Linux wheels upload usage events to
``mobile.events.data.microsoft.com`` from their own threads (6 DNS lookups in a 45 s session, and a
device id and an event store under ``~/.cache/Microsoft``), which ``disable_telemetry_events()``
does not stop; the variable does, when it is set before ONNX Runtime creates its environment.
Every attacker, and the utility net's ONNX path, imports this package first.
"""

import os as _os

_os.environ.setdefault("ORT_DISABLE_TELEMETRY", "1")

from attacks.base import (
    Attack,
    FitContext,
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
    "Attack",
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
