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


def mosaic(rgb: torch.Tensor, scale: torch.Tensor | None = None) -> torch.Tensor:
    """RGGB mosaic of (B,3,H,W) -> raw (B,1,H,W); each site's channel times scale[channel] if given (3,).

    Four strided copies, one per Bayer site: one pass over a single plane instead of selecting
    from all three channels.
    """
    raw = rgb.new_empty(rgb.shape[0], 1, rgb.shape[-2], rgb.shape[-1])
    for (dy, dx), channel in (((0, 0), 0), ((0, 1), 1), ((1, 0), 1), ((1, 1), 2)):
        plane = rgb[:, channel, dy::2, dx::2]
        raw[:, 0, dy::2, dx::2] = plane if scale is None else plane * scale[channel]
    return raw


def demosaic_bilinear(raw: torch.Tensor) -> torch.Tensor:
    """Bilinear demosaic of an RGGB raw image (B,1,H,W) -> (B,3,H,W).

    The classic bilinear interpolation (OpenCV's COLOR_Bayer*2RGB in the interior): a missing
    green is the mean of its 4 green neighbours, a missing red/blue the mean of its 2 or 4
    red/blue neighbours, with reflect-101 borders. Each of the four Bayer sites is handled apart:
    its neighbours of one colour are stride-2 views of the once-padded raw plane, so every output
    value is formed once and written in place (no masked full planes, no channel concatenation).
    An odd height or width is first reflect-padded by one row/column, which supplies exactly the
    neighbour the border needs, and cropped after.
    """
    h, w = raw.shape[-2:]
    if h % 2 or w % 2:
        return demosaic_bilinear(F.pad(raw, (0, w % 2, 0, h % 2), mode="reflect"))[..., :h, :w]
    padded = F.pad(raw, (1, 1, 1, 1), mode="reflect")[:, 0]  # (B, H+2, W+2); raw[y, x] at [y+1, x+1]
    # The padded plane's four phases (every other row and column), each copied contiguous once: the
    # neighbour views below then read unit-stride rows, faster than stride-2 views of the padded plane
    # and the same values (docs/history.md).
    phases = [[padded[:, py::2, px::2].contiguous() for px in (0, 1)] for py in (0, 1)]

    def at(y: int, x: int) -> torch.Tensor:
        """raw[2i + y, 2j + x] for every sub-pixel (i, j), y and x in -1..2 (border reflected)."""
        py, px = 1 + y, 1 + x
        return phases[py % 2][px % 2][:, py // 2:py // 2 + h // 2, px // 2:px // 2 + w // 2]

    out = raw.new_empty(raw.shape[0], 3, h, w)
    # Sites: R at (0, 0), G at (0, 1) and (1, 0), B at (1, 1).
    out[:, 0, 0::2, 0::2] = at(0, 0)
    out[:, 0, 0::2, 1::2] = 0.5 * (at(0, 0) + at(0, 2))
    out[:, 0, 1::2, 0::2] = 0.5 * (at(0, 0) + at(2, 0))
    out[:, 0, 1::2, 1::2] = 0.25 * (at(0, 0) + at(0, 2) + at(2, 0) + at(2, 2))
    out[:, 1, 0::2, 0::2] = 0.25 * (at(0, -1) + at(0, 1) + at(-1, 0) + at(1, 0))
    out[:, 1, 0::2, 1::2] = at(0, 1)
    out[:, 1, 1::2, 0::2] = at(1, 0)
    out[:, 1, 1::2, 1::2] = 0.25 * (at(0, 1) + at(2, 1) + at(1, 0) + at(1, 2))
    out[:, 2, 0::2, 0::2] = 0.25 * (at(-1, -1) + at(-1, 1) + at(1, -1) + at(1, 1))
    out[:, 2, 0::2, 1::2] = 0.5 * (at(-1, 1) + at(1, 1))
    out[:, 2, 1::2, 0::2] = 0.5 * (at(1, -1) + at(1, 1))
    out[:, 2, 1::2, 1::2] = at(1, 1)
    return out


def quantize_ste(x: torch.Tensor) -> torch.Tensor:
    """Round to integers with a straight-through gradient (twice differentiable: it is the identity).

    Without a graph it is ``torch.round`` itself: ``x + (round(x) - x)`` is exactly ``round(x)`` in
    floating point (the difference of two numbers within a factor of two is exact, and so is their sum)."""
    if not (torch.is_grad_enabled() and x.requires_grad):
        return torch.round(x)
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
        # Mosaic first, then clip: the same values (the scale is positive) on one plane instead of three.
        mean = mosaic(irradiance, self.electrons_per_unit().to(irradiance)).clamp(min=0.0)
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
