"""The camera's PSF and gain estimated from known (sensor image, sharp scene) pairs.

A known-pairs attacker is not given the PSF, but its pairs determine it: per channel c the sensor
image is ``y_c = g_c (x_c * h_c) + noise`` (``h_c`` sums to 1), so in the Fourier domain the
least-squares estimate over the pairs i is

    G_c H_c(f) = sum_i Y_ic(f) conj(X_ic(f)) / (sum_i |X_ic(f)|^2 + eps_c),

with ``eps_c`` a small fraction (``RIDGE``) of the mean scene power, which only matters where no
scene has power. Both images are multiplied by one 2-D Hann window first, so the FFT's wrap-around
sees no edge (the window varies slowly across the PSF's support, so ``w y ~ g (w x) * h``). The
estimate is brought back to the image domain, centred and cropped to ``size_px`` (odd). Away from
the PSF's support it is noise, symmetric about 0: its scale ``sigma_c`` is measured on the negative
values, and every value below ``THRESHOLD`` sigma is set to 0 (measured on 8 synthetic 256 x 512
scenes through ``defocus``: keeping all positive values overstates the gain by 38 %; at 3 sigma the
gain is within 3 % and the L1 distance to the optical PSF 0.12-0.17). Its sum is the gain ``g_c``, and it
is normalised to sum 1. What it measures
is the effective PSF of the whole pipeline up to the demosaicked image (lens and bilinear
demosaicking together), which is what a restorer of demosaicked images needs.
"""

from __future__ import annotations

import torch
from torch import Tensor

__all__ = ["RIDGE", "THRESHOLD", "estimate_psf"]

RIDGE = 1e-4
"""Regulariser of the least-squares estimate, relative to the mean scene power per frequency."""

THRESHOLD = 3.0
"""Kernel values below this many noise sigmas are set to 0."""


def estimate_psf(sensor: Tensor, sharp: Tensor, size_px: int) -> tuple[Tensor, Tensor]:
    """PSF (3, size_px, size_px) summing to 1 per channel, and gain (3,), from aligned pairs.

    Args:
        sensor: Sensor images (N, 3, H, W) in [0, 1].
        sharp: The sharp scenes they were taken of, (N, 3, H, W).
        size_px: Odd side of the estimated PSF, at most min(H, W).
    """
    if sensor.shape != sharp.shape or sensor.ndim != 4 or sensor.shape[1] != 3:
        raise ValueError(f"estimate_psf needs aligned (N, 3, H, W) pairs, got {tuple(sensor.shape)} and {tuple(sharp.shape)}")
    h, w = sensor.shape[-2:]
    if size_px % 2 == 0 or size_px > min(h, w):
        raise ValueError(f"estimate_psf: size_px must be odd and at most {min(h, w)}, got {size_px}")
    window = torch.outer(torch.hann_window(h, periodic=False, dtype=torch.float64),
                         torch.hann_window(w, periodic=False, dtype=torch.float64))
    cross = torch.zeros(3, h, w // 2 + 1, dtype=torch.complex128)
    power = torch.zeros(3, h, w // 2 + 1, dtype=torch.float64)
    for i in range(sensor.shape[0]):  # one pair at a time keeps the transforms small
        y = torch.fft.rfft2(sensor[i].double() * window)
        x = torch.fft.rfft2(sharp[i].double() * window)
        cross += y * x.conj()
        power += x.abs() ** 2
    eps = RIDGE * power.mean(dim=(-2, -1), keepdim=True)
    kernel = torch.fft.irfft2(cross / (power + eps), s=(h, w))
    r = size_px // 2
    kernel = torch.roll(kernel, shifts=(r, r), dims=(-2, -1))[:, :size_px, :size_px]
    negative = kernel.clamp_max(0.0)
    sigma = (negative.pow(2).sum(dim=(-2, -1)) / (kernel < 0).sum(dim=(-2, -1)).clamp_min(1)).sqrt()
    kernel = torch.where(kernel > THRESHOLD * sigma[:, None, None], kernel, torch.zeros_like(kernel))
    gain = kernel.sum(dim=(-2, -1))
    return (kernel / gain[:, None, None]).float(), gain.float()
