"""``identity``: the no-attack baseline, the sensor image white-balanced and nothing else.

Every real attack must beat it. The sensor's quantum efficiency tints its images (green
strongest, red weakest); a viewer of the sensor images corrects that before looking, and so
did the paper for its sensor-access attacks ("we correct the white balance manually to
compensate for the tint introduced by the physical sensor model", Sec. 4.2). The correction
here is that one: each channel divided by the sensor's known per-channel gain
(``lens.gain()``: expected sensor value per unit scene radiance), the correction a careful
manual balance converges to. The gain belongs to the sensor (quantum efficiency, exposure),
not to the optics: every lens in the suite with the same sensor and aperture shares it, so
using it reveals nothing about the lens's PSF and the threat model stays sensor access. The
uncorrected image is the ``raw`` reference row; the image-only estimate is ``gray-world``.
"""

from __future__ import annotations

from typing import Any, ClassVar

from torch import Tensor

from attacks.base import FitContext, FitReport, Restorer, ThreatModel

__all__ = ["Identity", "divide_by_gain"]


def divide_by_gain(sensor: Tensor, gain: Tensor) -> Tensor:
    """White balance by a known per-channel gain, clamped to [0, 1].

    Args:
        sensor: Sensor images, shape (B, 3, H, W), values in [0, 1].
        gain: Expected sensor value per unit scene radiance, shape (3,), positive.

    Returns:
        Scene-radiance estimate ``sensor / gain`` per channel, shape (B, 3, H, W) in [0, 1].
    """
    gain = gain.to(device=sensor.device, dtype=sensor.dtype)
    return (sensor / gain[:, None, None]).clamp(0.0, 1.0)


class Identity(Restorer):
    """Returns the sensor image divided by the sensor's per-channel gain (no deblurring)."""

    name: ClassVar[str] = "identity"
    threat_model: ClassVar[ThreatModel] = ThreatModel.SENSOR_ACCESS
    requires: ClassVar[frozenset[str]] = frozenset({"lens"})

    def __init__(self) -> None:
        self._gain: Tensor | None = None

    def fit(self, ctx: FitContext) -> FitReport:
        """Store the sensor's per-channel gain ``ctx.lens.gain()`` (3,)."""
        assert ctx.lens is not None  # guaranteed by the `requires` check that wraps fit
        self._gain = ctx.lens.gain().detach().cpu()
        return FitReport()

    def restore(self, sensor: Tensor) -> Tensor:
        """White-balanced ``sensor``: (B, 3, H, W) in [0, 1] -> (B, 3, H, W) in [0, 1]."""
        if self._gain is None:
            raise RuntimeError(f"{self.name}: call fit(FitContext(lens=...)) before restore()")
        return divide_by_gain(sensor, self._gain)

    def describe(self) -> dict[str, Any]:
        """Configuration: the white balance used."""
        return {**super().describe(), "white_balance": "divide-by-known-sensor-gain"}
