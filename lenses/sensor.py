"""Physical sensor model (after Hasinoff's noise model, the paper's ref. [16]).

irradiance in [0,1] -> intensity scale (D / D_ref)^2 -> RGGB colour filter -> electrons with
per-channel quantum efficiency -> shot + read noise -> full-well clip -> 10-bit ADC -> bilinear
demosaic -> RGB sensor image in [0,1].
"""

from __future__ import annotations

import torch
import torch.nn.functional as F

from lenses.spec import SensorSpec

def bayer_masks(height: int, width: int, device: torch.device | str = "cpu",
                dtype: torch.dtype = torch.float32) -> torch.Tensor:
    """RGGB colour-filter masks (3, H, W): R at (even row, even col), B at (odd, odd), G elsewhere."""
    rows = torch.arange(height, device=device)[:, None] % 2
    cols = torch.arange(width, device=device)[None, :] % 2
    r = (rows == 0) & (cols == 0)
    b = (rows == 1) & (cols == 1)
    return torch.stack([r, ~(r | b), b]).to(dtype)


def mosaic(rgb: torch.Tensor) -> torch.Tensor:
    """RGGB mosaic of (B,3,H,W) -> raw (B,1,H,W)."""
    masks = bayer_masks(rgb.shape[-2], rgb.shape[-1], rgb.device, torch.bool)
    return torch.where(masks[0], rgb[:, 0], torch.where(masks[2], rgb[:, 2], rgb[:, 1])).unsqueeze(1)


def _sum4(p: torch.Tensor, offsets: tuple[tuple[int, int], ...]) -> torch.Tensor:
    """Sum of a reflect-padded plane (..., H+2, W+2) shifted by each (dy, dx), cropped to (H, W)."""
    h, w = p.shape[-2] - 2, p.shape[-1] - 2
    return sum(p[..., 1 + dy:1 + dy + h, 1 + dx:1 + dx + w] for dy, dx in offsets)  # type: ignore[return-value]


def demosaic_bilinear(raw: torch.Tensor) -> torch.Tensor:
    """Bilinear demosaic of an RGGB raw image (B,1,H,W) -> (B,3,H,W).

    The classic bilinear interpolation (OpenCV's COLOR_Bayer*2RGB in the interior): a missing
    green is the mean of its 4 green neighbours, a missing red/blue the mean of its 2 or 4
    red/blue neighbours. Written as shifted sums of reflect-101-padded planes (the padding keeps
    the Bayer phase), several times faster than a depthwise conv2d on the CPU.
    """
    masks = bayer_masks(raw.shape[-2], raw.shape[-1], raw.device, raw.dtype)
    planes = F.pad(raw * masks, (1, 1, 1, 1), mode="reflect")  # (B,3,H+2,W+2)
    cross = ((-1, 0), (1, 0), (0, -1), (0, 1))
    diag = ((-1, -1), (-1, 1), (1, -1), (1, 1))
    rb = planes[:, 0::2]
    rb_full = rb[..., 1:-1, 1:-1] + 0.5 * _sum4(rb, cross) + 0.25 * _sum4(rb, diag)
    g = planes[:, 1:2]
    g_full = g[..., 1:-1, 1:-1] + 0.25 * _sum4(g, cross)
    return torch.cat([rb_full[:, :1], g_full, rb_full[:, 1:]], dim=1)


def quantize_ste(x: torch.Tensor) -> torch.Tensor:
    """Round to integers with a straight-through gradient (twice differentiable: it is the identity)."""
    return x + (torch.round(x) - x).detach()


class Sensor(torch.nn.Module):
    """RGB irradiance (B,3,H,W) in [0,1] -> demosaicked sensor image (B,3,H,W) in [0,1]."""

    def __init__(self, spec: SensorSpec, aperture_diameter_mm: float):
        super().__init__()
        self.spec = spec
        self.area_scale = (aperture_diameter_mm / spec.reference_aperture_diameter_mm) ** 2
        self.register_buffer("qe", torch.tensor(spec.quantum_efficiency), persistent=False)
        self.levels = 2**spec.adc_bits - 1

    def electrons_per_unit(self) -> torch.Tensor:
        """Mean electrons per unit irradiance, per channel (3,)."""
        return self.spec.white_level_photons * self.area_scale * self.qe

    def gain(self) -> torch.Tensor:
        """Expected sensor value per unit irradiance, per channel (3,): the tint a camera shows."""
        return self.electrons_per_unit() / self.spec.full_well_e

    def raw_electrons(self, irradiance: torch.Tensor, generator: torch.Generator | None = None,
                      eps: torch.Tensor | None = None) -> torch.Tensor:
        """Noisy, clipped electron counts of the RGGB raw image (B,1,H,W).

        Shot (Poisson, variance = mean) and read (Gaussian) noise are drawn as one reparameterised
        Gaussian mean + sqrt(mean + read^2) * eps: the same first two moments, differentiable in the
        mean and finite where the mean is 0. `eps` (B,1,H,W) standard normal draws replace the
        draw from `generator` for a caller that ties the noise to pixel positions (so that a window
        of a frame sees the frame's own noise).
        """
        mean = mosaic(irradiance.clamp(min=0.0) * self.electrons_per_unit()[:, None, None].to(irradiance))
        if eps is None:
            eps = torch.randn(mean.shape, generator=generator, device=mean.device, dtype=mean.dtype)
        elif eps.shape != mean.shape:
            raise ValueError(f"eps must have the raw image's shape {tuple(mean.shape)}, got {tuple(eps.shape)}")
        noisy = mean + torch.sqrt(mean + self.spec.read_noise_e**2) * eps
        return noisy.clamp(0.0, self.spec.full_well_e)

    def forward(self, irradiance: torch.Tensor, generator: torch.Generator | None = None,
                eps: torch.Tensor | None = None) -> torch.Tensor:
        electrons = self.raw_electrons(irradiance, generator, eps)
        digital = quantize_ste(electrons * (self.levels / self.spec.full_well_e))
        return demosaic_bilinear(digital / self.levels)
