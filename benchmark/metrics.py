"""Image-restoration metrics computed by the runner, identically for every attacker.

PSNR and SSIM follow scikit-image's definitions (`skimage.metrics.peak_signal_noise_ratio` and
`structural_similarity(..., gaussian_weights=True, sigma=1.5, use_sample_covariance=False,
data_range=1, channel_axis=...)`, i.e. Wang et al. 2004), vectorised in torch.
"""

from __future__ import annotations

import torch
import torch.nn.functional as F

_SIGMA = 1.5
_RADIUS = int(3.5 * _SIGMA + 0.5)  # scikit-image's gaussian truncation (truncate=3.5): 11 taps


def psnr(x: torch.Tensor, ref: torch.Tensor, data_range: float = 1.0) -> torch.Tensor:
    """PSNR in dB per image of (B,C,H,W) tensors; inf where identical."""
    mse = ((x.double() - ref.double()) ** 2).flatten(1).mean(dim=1)
    return 10 * torch.log10(data_range**2 / mse)


def _gaussian_window(dtype: torch.dtype, device: torch.device) -> torch.Tensor:
    t = torch.arange(-_RADIUS, _RADIUS + 1, dtype=dtype, device=device)
    w = torch.exp(-0.5 * (t / _SIGMA) ** 2)
    return w / w.sum()


def _filter(x: torch.Tensor, w: torch.Tensor) -> torch.Tensor:
    """Separable Gaussian filter, 'valid' region only (scikit-image crops that border anyway)."""
    c = x.shape[1]
    x = F.conv2d(x, w.view(1, 1, -1, 1).expand(c, 1, -1, 1), groups=c)
    return F.conv2d(x, w.view(1, 1, 1, -1).expand(c, 1, 1, -1), groups=c)


def ssim(x: torch.Tensor, ref: torch.Tensor, data_range: float = 1.0) -> torch.Tensor:
    """Mean SSIM per image of (B,C,H,W) tensors (channels averaged), as scikit-image computes it."""
    x, ref = x.double(), ref.double()
    if min(x.shape[-2:]) < 2 * _RADIUS + 1:
        raise ValueError(f"SSIM needs images of at least {2 * _RADIUS + 1} px per side, got {tuple(x.shape[-2:])}")
    w = _gaussian_window(x.dtype, x.device)
    mu_x, mu_y = _filter(x, w), _filter(ref, w)
    sxx = _filter(x * x, w) - mu_x**2
    syy = _filter(ref * ref, w) - mu_y**2
    sxy = _filter(x * ref, w) - mu_x * mu_y
    c1, c2 = (0.01 * data_range) ** 2, (0.03 * data_range) ** 2
    s = ((2 * mu_x * mu_y + c1) * (2 * sxy + c2)) / ((mu_x**2 + mu_y**2 + c1) * (sxx + syy + c2))
    return s.flatten(1).mean(dim=1)


def finite_mean(values: torch.Tensor) -> float:
    """Mean of per-image values, as a float. +inf (the PSNR of an exact copy) stays inf; NaN (an
    output that is not a number) is never scored: ValueError."""
    v = values.double()
    if bool(torch.isnan(v).any()):
        raise ValueError(f"{int(torch.isnan(v).sum())} of {v.numel()} per-image values are NaN; "
                         "a non-finite output is not scored")
    return float(v.mean())
