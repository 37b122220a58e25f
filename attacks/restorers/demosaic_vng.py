"""``demosaic-vng``: re-demosaic the sensor's own Bayer samples better, then white-balance.

The suite's sensor hands out a bilinearly demosaicked image (``lenses.sensor``). Bilinear
demosaicking keeps every measured sample at its own site (a missing value is a mean of
neighbours; a measured one is copied), so the RGGB mosaic comes back exactly from the
sensor image: R at (even row, even col), B at (odd, odd), G elsewhere, each value an ADC
count / (2^bits - 1). This attacker takes those samples and demosaicks them again with
OpenCV's variable-number-of-gradients (VNG, Chang et al. 1999) or edge-aware interpolation,
which interpolate along edges instead of across them (less zipper and colour fringing on
plate characters), then divides by the sensor's known per-channel gain as ``identity`` does.

OpenCV names a Bayer pattern by the colours of the second row's second and third pixels, so
our RGGB layout (R at (0, 0)) is OpenCV's "BG" (``COLOR_BayerBG2RGB_*``);
tests/attacks/restorers/test_demosaic_vng.py checks the channel order on a synthetic image. VNG takes
8-bit data only, so the 10-bit counts are rounded to 8 bits for it (a step of 4 counts, below
the shot noise of any pixel brighter than ~1 % of full scale); edge-aware takes 16-bit.

Threat model: sensor access. The Bayer layout, the ADC depth and the gain are properties of
the sensor shared by every lens, not of the optics.
"""

from __future__ import annotations

from typing import Any, ClassVar, Literal

import cv2
import numpy as np
import torch
from torch import Tensor

from attacks.base import FitContext, FitReport, Restorer, ThreatModel
from attacks.restorers.identity import divide_by_gain
from lenses.sensor import mosaic

__all__ = ["DemosaicVNG", "demosaic_opencv", "recover_mosaic"]

# OpenCV's codes for our RGGB layout (OpenCV calls it "BG", see the module docs).
_CODES = {"vng": cv2.COLOR_BayerBG2RGB_VNG, "ea": cv2.COLOR_BayerBG2RGB_EA}
# Each method's input depth: VNG is implemented for 8-bit data only.
_DEPTHS = {"vng": (np.uint8, 255), "ea": (np.uint16, 65535)}
Method = Literal["vng", "ea"]


def recover_mosaic(sensor: Tensor, adc_bits: int = 10) -> Tensor:
    """The RGGB raw samples of bilinearly demosaicked sensor images, in ADC counts.

    Args:
        sensor: Sensor images, shape (B, 3, H, W), values in [0, 1] (count / (2^bits - 1)).
        adc_bits: Bits of the sensor's ADC.

    Returns:
        Raw mosaic, shape (B, 1, H, W), float64 whole numbers in [0, 2^bits - 1]: the sample of
        each pixel's own colour, rounded to the nearest count (exact for images made by
        ``lenses.sensor.Sensor``).
    """
    levels = 2**adc_bits - 1
    return torch.round(mosaic(sensor.detach().to(torch.float64)) * levels).clamp(0, levels)


def demosaic_opencv(raw_counts: Tensor, adc_bits: int = 10, method: Method = "vng") -> Tensor:
    """Demosaic RGGB raw counts with OpenCV.

    Args:
        raw_counts: Raw mosaic, shape (B, 1, H, W), ADC counts in [0, 2^bits - 1]; H, W >= 2.
        adc_bits: Bits of the ADC that produced the counts.
        method: "vng" (variable number of gradients, 8-bit) or "ea" (edge-aware, 16-bit).

    Returns:
        RGB images, shape (B, 3, H, W), float32 in [0, 1] (count / (2^bits - 1)), on the
        device of ``raw_counts``.
    """
    if method not in _CODES:
        raise ValueError(f"demosaic method {method!r} is unknown; valid: {sorted(_CODES)}")
    if raw_counts.ndim != 4 or raw_counts.shape[1] != 1 or min(raw_counts.shape[-2:]) < 2:
        raise ValueError(f"raw_counts must be (B, 1, H, W) with H, W >= 2, got {tuple(raw_counts.shape)}")
    dtype, top = _DEPTHS[method]
    levels = 2**adc_bits - 1
    scaled = np.rint(raw_counts[:, 0].detach().cpu().numpy().astype(np.float64) * (top / levels)).astype(dtype)
    rgb = np.stack([cv2.cvtColor(np.ascontiguousarray(plane), _CODES[method]) for plane in scaled])
    out = torch.from_numpy(rgb.astype(np.float32) / top).permute(0, 3, 1, 2).contiguous()
    return out.to(raw_counts.device)


class DemosaicVNG(Restorer):
    """Recovers the Bayer mosaic from the sensor image, re-demosaicks it with OpenCV (VNG by
    default) and divides by the sensor's per-channel gain; no deblurring.

    Options:
        method: "vng" (default) or "ea" (OpenCV's edge-aware demosaic on 16-bit data).
    """

    name: ClassVar[str] = "demosaic-vng"
    threat_model: ClassVar[ThreatModel] = ThreatModel.SENSOR_ACCESS
    requires: ClassVar[frozenset[str]] = frozenset({"lens"})

    def __init__(self, method: Method = "vng") -> None:
        if method not in _CODES:
            raise ValueError(f"{self.name}: method {method!r} is unknown; valid: {sorted(_CODES)}")
        self.method = method
        self._gain: Tensor | None = None
        self._adc_bits = 10

    def fit(self, ctx: FitContext) -> FitReport:
        """Store the sensor's gain (3,) and ADC depth (from the lens spec when it has one)."""
        assert ctx.lens is not None  # guaranteed by the `requires` check that wraps fit
        self._gain = ctx.lens.gain().detach().cpu()
        sensor_spec = getattr(getattr(ctx.lens, "spec", None), "sensor", None)
        self._adc_bits = int(getattr(sensor_spec, "adc_bits", 10))
        return FitReport()

    def restore(self, sensor: Tensor) -> Tensor:
        """Scene estimate from ``sensor`` (B, 3, H, W) in [0, 1]: (B, 3, H, W) in [0, 1]."""
        if self._gain is None:
            raise RuntimeError(f"{self.name}: call fit(FitContext(lens=...)) before restore()")
        raw = recover_mosaic(sensor, self._adc_bits)
        rgb = demosaic_opencv(raw, self._adc_bits, self.method).to(sensor.dtype)
        return divide_by_gain(rgb, self._gain)

    def describe(self) -> dict[str, Any]:
        """Configuration: the demosaic method and the white balance."""
        return {**super().describe(), "method": self.method, "adc_bits": self._adc_bits,
                "white_balance": "divide-by-known-sensor-gain"}
