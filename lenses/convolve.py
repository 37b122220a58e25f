"""Image formation: per-channel convolution of a scene with the lens PSF.

Same-size output with reflect padding (a border that continues the scene rather than darkening
it). Direct convolution for small PSFs, FFT for large ones; both give the same result.
"""

from __future__ import annotations

import torch
import torch.nn.functional as F
from scipy.fft import next_fast_len

# Above this PSF size the FFT path is faster on the CPU at 512 x 1024 (measured by
# tests/speed/test_lens_speed.py::test_convolution_crossover).
FFT_THRESHOLD_PX = 15
# Spectrum bytes per chunk of the no-grad FFT convolution: each temporary stays well under glibc's
# 32 MiB mmap ceiling, so it is reused from the heap instead of page-faulted in on every call.
CHUNK_BYTES = 16 << 20


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


def fft_shape(height: int, width: int, psf_size_px: int) -> tuple[int, int]:
    """Transform size (h, w) for an image of height x width convolved with a K x K PSF.

    At least the reflect-padded size (so the circular wrap only touches the padding, which is
    cropped away), rounded up to a size with small prime factors only: an awkward size (e.g. 1062)
    costs 2-3x.
    """
    r = psf_size_px // 2
    return next_fast_len(height + 2 * r, real=True), next_fast_len(width + 2 * r, real=True)


def psf_otf(psf: torch.Tensor, shape: tuple[int, int]) -> torch.Tensor:
    """rfft2 of the PSF (C,K,K) centred on index (0, 0) of an (h, w) grid: complex (C, h, w//2+1)."""
    k = psf.shape[-1]
    kernel = psf.new_zeros(psf.shape[0], *shape)
    kernel[:, :k, :k] = psf
    kernel = torch.roll(kernel, shifts=(-(k // 2), -(k // 2)), dims=(1, 2))
    return torch.fft.rfft2(kernel)


def apply_otf(x: torch.Tensor, otf: torch.Tensor, psf_size_px: int) -> torch.Tensor:
    """Convolve x (B,C,H,W) with the PSF whose psf_otf on fft_shape(H, W, K) is `otf`, same-size
    output with reflect padding (the circular wrap only touches the padding, cropped away).

    Without autograd, a few images at a time (at most CHUNK_BYTES of spectrum) into a preallocated
    output, multiplying each spectrum in place: the temporaries of a whole batch of 8 at 512 x 1024
    (each over glibc's 32 MiB mmap ceiling, so mapped afresh on every call) cost ~450 MB of page
    faults per call, more than the transforms themselves; small images still go many per call.
    """
    r = psf_size_px // 2
    h, w = x.shape[-2:]
    shape = fft_shape(h, w, psf_size_px)
    spectrum_dtype = torch.promote_types(otf.dtype, torch.complex64 if x.dtype != torch.float64 else torch.complex128)
    if (torch.is_grad_enabled() and (x.requires_grad or otf.requires_grad)) or spectrum_dtype != otf.dtype:
        y = torch.fft.irfft2(torch.fft.rfft2(_pad(x, r), s=shape) * otf, s=shape)
        return y[..., r:r + h, r:r + w]
    out = x.new_empty(x.shape, dtype=otf.real.dtype)
    per_image = x.shape[1] * otf.shape[-2] * otf.shape[-1] * otf.element_size()
    step = max(1, CHUNK_BYTES // per_image)
    for i in range(0, x.shape[0], step):
        spectrum = torch.fft.rfft2(_pad(x[i:i + step], r), s=shape)
        spectrum *= otf
        out[i:i + step] = torch.fft.irfft2(spectrum, s=shape)[..., r:r + h, r:r + w]
    return out


def convolve_fft(x: torch.Tensor, psf: torch.Tensor) -> torch.Tensor:
    """Per-channel convolution through real FFTs. Same contract as convolve_direct."""
    k = psf.shape[-1]
    return apply_otf(x, psf_otf(psf.to(x.dtype), fft_shape(x.shape[-2], x.shape[-1], k)), k)


def convolve(x: torch.Tensor, psf: torch.Tensor) -> torch.Tensor:
    """Convolve each channel of x (B,C,H,W) with psf (C,K,K), choosing FFT or direct by K."""
    if psf.ndim != 3 or psf.shape[0] != x.shape[1] or psf.shape[-1] % 2 != 1 or psf.shape[-1] != psf.shape[-2]:
        raise ValueError(f"psf must be (C, K, K) with odd K and C = {x.shape[1]}, got {tuple(psf.shape)}")
    return convolve_fft(x, psf) if uses_fft(psf.shape[-1]) else convolve_direct(x, psf)


def uses_fft(psf_size_px: int) -> bool:
    """Whether convolve takes the FFT path for a K x K PSF."""
    return psf_size_px > FFT_THRESHOLD_PX
