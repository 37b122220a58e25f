"""Generic camera degradations that know nothing of a particular lens (for ``nafnet-generic``).

A sensor-access attacker has no pairs from the camera under test, so it trains on degradations
drawn from broad families, the way GoPro-style deblurring models are meant to generalise:

- blur: identity (so a sharp camera is left alone), isotropic Gaussian, linear motion and
  defocus disk kernels, with sizes spanning "barely blurred" to a ~15 px blur circle;
- colour: a random per-channel gain (tint and exposure), as different sensors' quantum
  efficiencies and exposures give;
- noise: Poisson-Gaussian (signal-dependent shot noise plus read noise) with levels drawn
  log-uniformly, then 10-bit quantisation, and for half the images an RGGB mosaic with
  bilinear demosaicking (a generic raw pipeline, not the lens's).

Every draw uses an explicit ``torch.Generator``, so a training run is reproducible from its seed.
"""

from __future__ import annotations

import math

import torch
import torch.nn.functional as F
from torch import Tensor

from lenses.sensor import demosaic_bilinear, mosaic

__all__ = [
    "KERNEL_FAMILIES",
    "blur_per_image",
    "degrade",
    "disk_kernel",
    "gaussian_kernel",
    "motion_kernel",
    "random_kernels",
]

KERNEL_FAMILIES = ("identity", "gaussian", "motion", "disk")
"""Blur families, drawn with equal probability."""

_KERNEL_SIZE_PX = 31
# Ranges in pixels: the largest ones match the suite's ``defocus`` lens (~15 px blur circle).
_GAUSSIAN_SIGMA_PX = (0.3, 4.0)
_MOTION_LENGTH_PX = (2.0, 15.0)
_DISK_RADIUS_PX = (0.8, 8.0)
_TINT_GAIN = (0.4, 1.0)
_SHOT_VARIANCE = (1e-5, 1e-3)   # variance per unit signal, in [0, 1] units
_READ_SIGMA = (2e-4, 1e-2)      # read-noise standard deviation, in [0, 1] units
_ADC_LEVELS = 1023


def _grid(size_px: int, dtype: torch.dtype = torch.float32) -> tuple[Tensor, Tensor]:
    a = torch.arange(size_px, dtype=dtype) - size_px // 2
    return a[:, None].expand(size_px, size_px), a[None, :].expand(size_px, size_px)


def gaussian_kernel(sigma_px: float, size_px: int = _KERNEL_SIZE_PX) -> Tensor:
    """Isotropic Gaussian, shape (size_px, size_px), centred at [size_px // 2] * 2, sums to 1."""
    y, x = _grid(size_px)
    k = torch.exp(-(x**2 + y**2) / (2.0 * sigma_px**2))
    return k / k.sum()


def disk_kernel(radius_px: float, size_px: int = _KERNEL_SIZE_PX) -> Tensor:
    """Uniform disk (geometric defocus) of ``radius_px``, anti-aliased by 4x4 supersampling;
    shape (size_px, size_px), centred, sums to 1."""
    sub = 4
    a = (torch.arange(size_px * sub, dtype=torch.float32) + 0.5) / sub - size_px / 2.0
    inside = ((a[:, None] ** 2 + a[None, :] ** 2) <= radius_px**2).float()
    k = inside.reshape(size_px, sub, size_px, sub).mean(dim=(1, 3))
    return k / k.sum()


def motion_kernel(length_px: float, angle_rad: float, size_px: int = _KERNEL_SIZE_PX) -> Tensor:
    """Linear motion blur: a centred segment of ``length_px`` at ``angle_rad``, drawn with
    bilinear splats of 4 samples per pixel; shape (size_px, size_px), sums to 1."""
    n = max(2, int(math.ceil(length_px * 4)))
    t = torch.linspace(-length_px / 2.0, length_px / 2.0, n)
    xs = t * math.cos(angle_rad) + size_px // 2
    ys = t * math.sin(angle_rad) + size_px // 2
    k = torch.zeros(size_px, size_px)
    x0, y0 = xs.floor(), ys.floor()
    for dx in (0, 1):
        for dy in (0, 1):
            w = (1 - (xs - x0 - dx).abs()) * (1 - (ys - y0 - dy).abs())
            k.index_put_(((y0 + dy).long(), (x0 + dx).long()), w, accumulate=True)
    return k / k.sum()


def _uniform(generator: torch.Generator, low: float, high: float) -> float:
    return low + (high - low) * float(torch.rand((), generator=generator))


def _log_uniform(generator: torch.Generator, low: float, high: float) -> float:
    return math.exp(_uniform(generator, math.log(low), math.log(high)))


def random_kernels(n: int, generator: torch.Generator, size_px: int = _KERNEL_SIZE_PX) -> Tensor:
    """``n`` kernels (n, size_px, size_px), each from a family drawn uniformly from
    ``KERNEL_FAMILIES`` with a random size (module docs), each summing to 1."""
    kernels = []
    for _ in range(n):
        family = KERNEL_FAMILIES[int(torch.randint(len(KERNEL_FAMILIES), (), generator=generator))]
        if family == "identity":
            k = torch.zeros(size_px, size_px)
            k[size_px // 2, size_px // 2] = 1.0
        elif family == "gaussian":
            k = gaussian_kernel(_uniform(generator, *_GAUSSIAN_SIGMA_PX), size_px)
        elif family == "motion":
            k = motion_kernel(_uniform(generator, *_MOTION_LENGTH_PX), _uniform(generator, 0.0, math.pi), size_px)
        else:
            k = disk_kernel(_uniform(generator, *_DISK_RADIUS_PX), size_px)
        kernels.append(k)
    return torch.stack(kernels)


def blur_per_image(x: Tensor, kernels: Tensor) -> Tensor:
    """Convolve every channel of image i with ``kernels[i]`` (same-size output, reflect padding).

    Args:
        x: Images (B, C, H, W).
        kernels: (B, K, K), K odd, centred at [K // 2, K // 2].

    Returns:
        Blurred images (B, C, H, W). Via FFT on the padded grid; the circular wrap only touches
        the padding, which is cropped away.
    """
    b, c, h, w = x.shape
    r = kernels.shape[-1] // 2
    # Reflect needs pad < size; tiny images get their remaining margin by edge replication.
    ry, rx = min(r, h - 1), min(r, w - 1)
    xp = F.pad(x, (rx, rx, ry, ry), mode="reflect")
    xp = F.pad(xp, (r - rx, r - rx, r - ry, r - ry), mode="replicate")
    grid = xp.shape[-2:]
    k = kernels.new_zeros(b, *grid)
    k[:, : 2 * r + 1, : 2 * r + 1] = kernels
    k = torch.roll(k, shifts=(-r, -r), dims=(-2, -1)).to(x)
    y = torch.fft.irfft2(torch.fft.rfft2(xp) * torch.fft.rfft2(k)[:, None], s=grid)
    return y[..., r : r + h, r : r + w]


def degrade(sharp: Tensor, generator: torch.Generator) -> Tensor:
    """A generic camera's image of ``sharp``: random blur, tint, noise, quantisation, Bayer.

    Args:
        sharp: Scenes (B, 3, H, W) in [0, 1], H and W even (the Bayer pattern tiles 2x2).
        generator: CPU generator for every random draw.

    Returns:
        Degraded images (B, 3, H, W) in [0, 1], on ``sharp``'s device.
    """
    b = sharp.shape[0]
    blurred = blur_per_image(sharp, random_kernels(b, generator).to(sharp.device))
    gains = _TINT_GAIN[0] + (_TINT_GAIN[1] - _TINT_GAIN[0]) * torch.rand(b, 3, 1, 1, generator=generator)
    signal = blurred.clamp_min(0.0) * gains.to(sharp)
    shot = torch.tensor([_log_uniform(generator, *_SHOT_VARIANCE) for _ in range(b)]).view(b, 1, 1, 1).to(sharp)
    read = torch.tensor([_log_uniform(generator, *_READ_SIGMA) for _ in range(b)]).view(b, 1, 1, 1).to(sharp)
    eps = torch.randn(signal.shape, generator=generator).to(sharp)
    noisy = (signal + torch.sqrt(shot * signal + read**2) * eps).clamp(0.0, 1.0)
    noisy = torch.round(noisy * _ADC_LEVELS) / _ADC_LEVELS
    raw_pipeline = (torch.rand(b, generator=generator) < 0.5).to(sharp.device)
    demosaicked = demosaic_bilinear(mosaic(noisy))
    return torch.where(raw_pipeline.view(b, 1, 1, 1), demosaicked, noisy).clamp(0.0, 1.0)
