"""``identity``: the do-nothing attacker; every real attack must beat it."""

from __future__ import annotations

from typing import ClassVar

from torch import Tensor

from attacks.base import Restorer, ThreatModel


class Identity(Restorer):
    """Returns the sensor image as the scene estimate (the no-attack baseline)."""

    name: ClassVar[str] = "identity"
    threat_model: ClassVar[ThreatModel] = ThreatModel.SENSOR_ACCESS

    def restore(self, sensor: Tensor) -> Tensor:
        """Return a copy of ``sensor`` (B, 3, H, W) in [0, 1]; a copy so that a caller editing
        the output in place cannot corrupt the sensor batch other attackers still read."""
        return sensor.clone()
