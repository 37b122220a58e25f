"""``raw``: the uncorrected sensor image, a reference row rather than an attack.

It shows what the sensor hands over before anyone white-balances it. It is marked
``reference``: its rows have kind "reference" and never count as a lens's worst case (the
tint is not privacy; the white-balanced ``identity`` is the no-attack baseline).
"""

from __future__ import annotations

from typing import ClassVar

from torch import Tensor

from attacks.base import Restorer, ThreatModel

__all__ = ["Raw"]


class Raw(Restorer):
    """Returns the sensor image unchanged (a copy)."""

    name: ClassVar[str] = "raw"
    threat_model: ClassVar[ThreatModel] = ThreatModel.SENSOR_ACCESS
    reference: ClassVar[bool] = True

    def restore(self, sensor: Tensor) -> Tensor:
        """Return a copy of ``sensor`` (B, 3, H, W) in [0, 1]; a copy so that a caller editing
        the output in place cannot corrupt the sensor batch other attackers still read."""
        return sensor.clone()
