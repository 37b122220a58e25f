"""Image formation: per-channel convolution of a scene with the lens PSF.

Same-size output with reflect padding (a border that continues the scene rather than darkening
it). Direct convolution for small PSFs, FFT for large ones; both give the same result.
"""

from __future__ import annotations

import torch
import torch.nn.functional as F
from scipy.fft import next_fast_len

# Above this PSF size the FFT path is faster on the CPU at 512 x 1024 (measured by
# tests/benchmarks/test_lens_speed.py::test_convolution_crossover).
FFT_THRESHOLD_PX = 15


def _pad(x: torch.Tensor, r: int) -> torch.Tensor:
    """Reflect-pad by r on each side; where the image is smaller than r, the rest repeats the edge."""
    h, w = x.shape[-2:]
    ry, rx = min(r, h - 1), min(r, w - 1)
    x = F.pad(x, (rx, rx, ry, ry), mode="reflect")
    if ry < r or rx < r:
        x = F.pad(x, (r - rx, r - rx, r - ry, r - ry), mode="replicate")
    return x


def convolve_direct(x: torch.Tensor, psf: torch.Tensor) -> torch.Tensor:
    """Per-channel convolution by conv2d. x (B,C,H,W), psf (C,K,K), K odd -> (B,C,H,W)."""
    k = psf.shape[-1]
    weight = psf.flip(-1, -2).unsqueeze(1).to(x.dtype)  # conv2d correlates; flip to convolve
    return F.conv2d(_pad(x, k // 2), weight, groups=x.shape[1])


def convolve_fft(x: torch.Tensor, psf: torch.Tensor) -> torch.Tensor:
    """Per-channel convolution through rfft2. Same contract as convolve_direct.

    The circular wrap of the FFT only touches the padding, which is cropped away.
    """
    k = psf.shape[-1]
    r = k // 2
    xp = _pad(x, r)
    # Transform sizes with small prime factors only: an awkward size (e.g. 1062) costs 2-3x.
    h, w = next_fast_len(xp.shape[-2], real=True), next_fast_len(xp.shape[-1], real=True)
    kernel = torch.zeros(psf.shape[0], h, w, dtype=x.dtype, device=x.device)
    kernel[:, :k, :k] = psf.to(x.dtype)
    kernel = torch.roll(kernel, shifts=(-r, -r), dims=(1, 2))  # PSF centre to index (0, 0)
    y = torch.fft.irfft2(torch.fft.rfft2(xp, s=(h, w)) * torch.fft.rfft2(kernel), s=(h, w))
    return y[..., r:r + x.shape[-2], r:r + x.shape[-1]]


def convolve(x: torch.Tensor, psf: torch.Tensor) -> torch.Tensor:
    """Convolve each channel of x (B,C,H,W) with psf (C,K,K), choosing FFT or direct by K."""
    if psf.ndim != 3 or psf.shape[0] != x.shape[1] or psf.shape[-1] % 2 != 1 or psf.shape[-1] != psf.shape[-2]:
        raise ValueError(f"psf must be (C, K, K) with odd K and C = {x.shape[1]}, got {tuple(psf.shape)}")
    return convolve_fft(x, psf) if psf.shape[-1] > FFT_THRESHOLD_PX else convolve_direct(x, psf)
