"""The lens forward (convolution + sensor) as it was on 2026-11-22, before the speed work:
the oracle that the faster code must equal (within 1e-5) and the baseline of its speed
ratio. Frozen on purpose; only the tests import it.

Given the same PSF and noise generator it computes what lenses.Lens.forward computes: reflect-pad,
zero-padded rfft2 convolution with the OTF rebuilt on every call, then masked-plane RGGB mosaic,
reparameterised shot + read noise, 10-bit ADC and a masked-plane bilinear demosaic.
"""

from __future__ import annotations

import torch
import torch.nn.functional as F
from scipy.fft import next_fast_len

from lenses.spec import SensorSpec


def _pad(x: torch.Tensor, r: int) -> torch.Tensor:
    h, w = x.shape[-2:]
    ry, rx = min(r, h - 1), min(r, w - 1)
    x = F.pad(x, (rx, rx, ry, ry), mode="reflect")
    if ry < r or rx < r:
        x = F.pad(x, (r - rx, r - rx, r - ry, r - ry), mode="replicate")
    return x


def convolve(x: torch.Tensor, psf: torch.Tensor) -> torch.Tensor:
    k = psf.shape[-1]
    r = k // 2
    if k <= 15:
        return F.conv2d(_pad(x, r), psf.flip(-1, -2).unsqueeze(1).to(x.dtype), groups=x.shape[1])
    xp = _pad(x, r)
    h, w = next_fast_len(xp.shape[-2], real=True), next_fast_len(xp.shape[-1], real=True)
    kernel = torch.zeros(psf.shape[0], h, w, dtype=x.dtype, device=x.device)
    kernel[:, :k, :k] = psf.to(x.dtype)
    kernel = torch.roll(kernel, shifts=(-r, -r), dims=(1, 2))
    y = torch.fft.irfft2(torch.fft.rfft2(xp, s=(h, w)) * torch.fft.rfft2(kernel), s=(h, w))
    return y[..., r:r + x.shape[-2], r:r + x.shape[-1]]


def _masks(h: int, w: int, device: torch.device, dtype: torch.dtype) -> torch.Tensor:
    rows = torch.arange(h, device=device)[:, None] % 2
    cols = torch.arange(w, device=device)[None, :] % 2
    r = (rows == 0) & (cols == 0)
    b = (rows == 1) & (cols == 1)
    return torch.stack([r, ~(r | b), b]).to(dtype)


def mosaic(rgb: torch.Tensor) -> torch.Tensor:
    m = _masks(rgb.shape[-2], rgb.shape[-1], rgb.device, torch.bool)
    return torch.where(m[0], rgb[:, 0], torch.where(m[2], rgb[:, 2], rgb[:, 1])).unsqueeze(1)


def _sum4(p: torch.Tensor, offsets: tuple[tuple[int, int], ...]) -> torch.Tensor:
    h, w = p.shape[-2] - 2, p.shape[-1] - 2
    return sum(p[..., 1 + dy:1 + dy + h, 1 + dx:1 + dx + w] for dy, dx in offsets)  # type: ignore[return-value]


def demosaic(raw: torch.Tensor) -> torch.Tensor:
    planes = F.pad(raw * _masks(raw.shape[-2], raw.shape[-1], raw.device, raw.dtype), (1, 1, 1, 1), mode="reflect")
    cross = ((-1, 0), (1, 0), (0, -1), (0, 1))
    diag = ((-1, -1), (-1, 1), (1, -1), (1, 1))
    rb = planes[:, 0::2]
    rb_full = rb[..., 1:-1, 1:-1] + 0.5 * _sum4(rb, cross) + 0.25 * _sum4(rb, diag)
    g = planes[:, 1:2]
    g_full = g[..., 1:-1, 1:-1] + 0.25 * _sum4(g, cross)
    return torch.cat([rb_full[:, :1], g_full, rb_full[:, 1:]], dim=1)


def forward(x: torch.Tensor, psf: torch.Tensor, sensor: SensorSpec, aperture_diameter_mm: float,
            generator: torch.Generator | None = None) -> torch.Tensor:
    """Scene (B,3,H,W) -> sensor image (B,3,H,W) through PSF (3,K,K), as lenses.Lens did before the speed work."""
    area_scale = (aperture_diameter_mm / sensor.reference_aperture_diameter_mm) ** 2
    electrons_per_unit = sensor.white_level_photons * area_scale * torch.tensor(sensor.quantum_efficiency)
    irradiance = convolve(x, psf)
    mean = mosaic(irradiance.clamp(min=0.0) * electrons_per_unit[:, None, None].to(irradiance))
    eps = torch.randn(mean.shape, generator=generator, device=mean.device, dtype=mean.dtype)
    electrons = (mean + torch.sqrt(mean + sensor.read_noise_e**2) * eps).clamp(0.0, sensor.full_well_e)
    levels = 2**sensor.adc_bits - 1
    scaled = electrons * (levels / sensor.full_well_e)
    digital = scaled + (torch.round(scaled) - scaled).detach()
    return demosaic(digital / levels)
