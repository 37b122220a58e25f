"""``wiener-known-psf``: the attacker measured the camera's PSF and gain; Wiener deconvolution.

The deconvolution, its noise estimator and its fitted power-law scene prior are in
``attacks.backends.wiener`` (with their measured PSNR on a reference image).
"""

from __future__ import annotations

from typing import Any, ClassVar

import torch
from torch import Tensor

from attacks.backends.real_fft import OtfCache
from attacks.backends.wiener import ADC_NOISE_SIGMA, bayer_noise_sigma, wiener_chunks, wiener_deconvolve
from attacks.base import FitContext, FitReport, Restorer, ThreatModel

__all__ = ["WienerKnownPSF"]


class WienerKnownPSF(Restorer):
    """Divides out the measured per-channel gain and Wiener-deconvolves with the measured PSF.

    The noise level and scene spectrum are estimated from each sensor image (module docs).
    """

    name: ClassVar[str] = "wiener-known-psf"
    threat_model: ClassVar[ThreatModel] = ThreatModel.LENS_ACCESS
    requires: ClassVar[frozenset[str]] = frozenset({"lens"})

    def __init__(self) -> None:
        self._psf: OtfCache | None = None
        self._gain: Tensor | None = None

    def fit(self, ctx: FitContext) -> FitReport:
        """Measure the camera: store ``ctx.lens.psf()`` (3, K, K) and ``ctx.lens.gain()`` (3,)."""
        assert ctx.lens is not None  # guaranteed by the `requires` check that wraps fit
        self._psf = OtfCache(ctx.lens.psf().detach())
        self._gain = ctx.lens.gain().detach()
        return FitReport()

    def restore(self, sensor: Tensor) -> Tensor:
        """Scene estimate from ``sensor`` (B, 3, H, W) in [0, 1]: (B, 3, H, W) in [0, 1]."""
        if self._psf is None or self._gain is None:
            raise RuntimeError(f"{self.name}: call fit(FitContext(lens=...)) before restore()")
        gain = self._gain.to(device=sensor.device, dtype=sensor.dtype)
        # Lens access includes the sensor layout: the noise is measured on the raw RGGB sites.
        # A few images at a time keep every temporary small (attacks.backends.real_fft).
        deblurred = torch.cat([wiener_deconvolve(sensor[chunk], self._psf, sigma=bayer_noise_sigma(sensor[chunk]))
                               for chunk in wiener_chunks(sensor, self._psf.psf)])
        return (deblurred / gain[:, None, None]).clamp(0.0, 1.0)

    def describe(self) -> dict[str, Any]:
        """Configuration, including the estimators (there are no tunable options)."""
        return {
            **super().describe(),
            "noise_estimator": "haar-diagonal-mad-on-bayer-sites",
            "min_noise_sigma": ADC_NOISE_SIGMA,
            "signal_prior": "fitted-power-law",
            "padding": "reflect-psf-radius+edge-taper",
        }
