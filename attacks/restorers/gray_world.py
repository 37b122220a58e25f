"""``gray-world``: undo the sensor's colour tint with gray-world white balance, nothing else.

Gray-world assumes the average reflectance of a scene is achromatic, so each channel of an
image is scaled by ``target / mean_c`` where ``mean_c`` is that channel's mean and ``target``
is the mean of the three channel means (the image's mean intensity, equal-weight luminance).
Choosing that target (rather than, say, the green mean or Rec. 709 luma) leaves the overall
brightness unchanged before clamping, so the attacker only moves colour, not exposure.
"""

from __future__ import annotations

from typing import ClassVar

from torch import Tensor

from attacks.base import Restorer, ThreatModel

__all__ = ["GrayWorld", "gray_world_balance"]

# A channel whose mean is below this is treated as empty rather than amplified without bound.
_MIN_CHANNEL_MEAN = 1e-6


def gray_world_balance(x: Tensor) -> Tensor:
    """Gray-world white balance, per image, clamped to [0, 1].

    Args:
        x: Images, shape (B, 3, H, W), linear values in [0, 1].

    Returns:
        Balanced images, shape (B, 3, H, W) in [0, 1]: channel ``c`` of image ``b`` scaled by
        ``mean(x[b]) / mean(x[b, c])``, so (before clamping) all channel means equal the
        image's mean intensity, which is unchanged.
    """
    channel_means = x.mean(dim=(-2, -1), keepdim=True)
    target = channel_means.mean(dim=-3, keepdim=True)
    gains = target / channel_means.clamp_min(_MIN_CHANNEL_MEAN)
    return (x * gains).clamp(0.0, 1.0)


class GrayWorld(Restorer):
    """White-balances the sensor image (``gray_world_balance``); no deblurring."""

    name: ClassVar[str] = "gray-world"
    threat_model: ClassVar[ThreatModel] = ThreatModel.SENSOR_ACCESS

    def restore(self, sensor: Tensor) -> Tensor:
        """Balanced ``sensor``: (B, 3, H, W) in [0, 1] -> (B, 3, H, W) in [0, 1]."""
        return gray_world_balance(sensor)
