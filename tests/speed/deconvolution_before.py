"""Richardson-Lucy and Wiener deconvolution as they were on 2026-11-24, before the speed work:
the oracle that the faster code must equal (the equality tests of test_deconvolution_speed.py)
and the baseline of its speed ratio (test_deconvolution_speed.py). Frozen on purpose; only the tests
import it.

Both rebuild the full ``fft2`` OTF on every call and run ``torch.fft`` on the whole batch at once;
the restorers' ``restore`` is ``restore_wiener`` / ``restore_richardson_lucy`` here.
"""

from __future__ import annotations

import math
from collections.abc import Iterator

import torch
import torch.nn.functional as F
from scipy.fft import next_fast_len
from torch import Tensor

ADC_NOISE_SIGMA = 1.0 / (1023.0 * math.sqrt(12.0))
_MAD_TO_SIGMA = 0.6744897501960817
_N_BANDS = 24
_MIN_BAND_SNR = 2.0
_MIN_BAND_OTF_POWER = 1e-3
_ALPHA_RANGE = (1.0, 4.0)
_EPS = 1e-12

def psf_to_otf(psf: Tensor, shape: tuple[int, int]) -> Tensor:
    """Optical transfer function of a centred PSF on an ``shape`` grid (circular convolution).

    Args:
        psf: Shape (..., K_h, K_w), centre at [K_h // 2, K_w // 2], real.
        shape: (H, W) of the image grid the OTF applies to. A PSF larger than the grid wraps
            around (summed), which is the exact circular operator.

    Returns:
        Complex OTF, shape (..., H, W), full ``fft2`` layout (DC at [0, 0]).
    """
    k_h, k_w = psf.shape[-2:]
    height, width = shape
    rows = (torch.arange(k_h, device=psf.device) - k_h // 2) % height
    cols = (torch.arange(k_w, device=psf.device) - k_w // 2) % width
    flat_index = (rows[:, None] * width + cols[None, :]).reshape(-1)
    grid = psf.new_zeros(*psf.shape[:-2], height * width)
    grid.index_add_(-1, flat_index, psf.reshape(*psf.shape[:-2], k_h * k_w))
    return torch.fft.fft2(grid.reshape(*psf.shape[:-2], height, width))

def estimate_noise_sigma(y: Tensor, min_sigma: float = ADC_NOISE_SIGMA) -> Tensor:
    """Standard deviation of additive white noise, per image and channel (robust MAD).

    Args:
        y: Images, shape (B, C, H, W) with H, W >= 2, any units.
        min_sigma: Floor on the estimate, in the units of ``y``.

    Returns:
        Sigma, shape (B, C), ``median(|HH|) / 0.6745`` over the finest orthonormal Haar
        diagonal coefficients HH, at least ``min_sigma``.
    """
    even = y[..., : y.shape[-2] // 2 * 2, : y.shape[-1] // 2 * 2]
    a, b = even[..., 0::2, 0::2], even[..., 0::2, 1::2]
    c, d = even[..., 1::2, 0::2], even[..., 1::2, 1::2]
    diagonal = (a - b - c + d) / 2.0
    mad = diagonal.abs().flatten(-2).median(dim=-1).values
    return (mad / _MAD_TO_SIGMA).clamp_min(min_sigma)

def bayer_noise_sigma(y: Tensor, min_sigma: float = ADC_NOISE_SIGMA) -> Tensor:
    """Noise sigma (B, 3) of a demosaicked RGGB sensor image, measured on the raw lattice.

    Bilinear demosaicking averages neighbours, which correlates the noise and hides it from the
    finest wavelet band of the full image (the MAD then reads several times too low and the
    filter amplifies noise). On each colour's own Bayer sites the values are the raw samples,
    whose noise is white: estimate there (R at (0,0), G at (0,1), B at (1,1)).
    """
    lattices = [y[:, 0:1, 0::2, 0::2], y[:, 1:2, 0::2, 1::2], y[:, 2:3, 1::2, 1::2]]
    return torch.cat([estimate_noise_sigma(lattice, min_sigma) for lattice in lattices], dim=1)

def power_law_nsr(
    y: Tensor, psf: Tensor, sigma: Tensor, grid_shape: tuple[int, int]
) -> Tensor:
    """Noise-to-signal ratio per frequency: white noise over a power-law scene spectrum.

    The scene spectrum ``S(f) = A |f|^-alpha`` is fitted per image and channel to the
    observed spectrum (module docs); where too little of it is visible to fit (fewer than two
    usable bands) the scene is treated as flat and NSR is infinite away from DC.

    Args:
        y: Blurred noisy images, shape (B, C, H, W), unpadded.
        psf: Shape (C, K, K) or (K, K), centred at [K // 2, K // 2], channels sum to 1.
        sigma: Noise standard deviation, shape (B, C), in the units of ``y``.
        grid_shape: (H', W') of the (padded) grid the filter is applied on.

    Returns:
        NSR, shape (B, C, H', W' // 2 + 1) (``rfft2`` layout), dimensionless, 0 at DC.
    """
    height, width = y.shape[-2:]
    n_pixels = height * width
    window = torch.outer(
        torch.hann_window(height, periodic=False, dtype=y.dtype, device=y.device),
        torch.hann_window(width, periodic=False, dtype=y.dtype, device=y.device),
    )
    # Hann window and mean removal keep the border jump and DC from leaking into the high
    # frequencies, where dividing by a small |H|^2 would turn leakage into fake signal.
    centred = (y - y.mean(dim=(-2, -1), keepdim=True)) * window
    periodogram = torch.fft.rfft2(centred).abs() ** 2 * (n_pixels / window.square().sum())
    otf_power = psf_to_otf(psf, (height, width))[..., : width // 2 + 1].abs() ** 2
    radius = _radial_frequency(height, width, y)
    edges = torch.logspace(
        math.log10(1.0 / min(height, width)), math.log10(0.5 * math.sqrt(2.0)), _N_BANDS + 1,
        dtype=y.dtype, device=y.device,
    )
    band = (torch.bucketize(radius.flatten(), edges) - 1).clamp(-1, _N_BANDS)
    inside = (band >= 0) & (band < _N_BANDS)
    band_power = _band_mean(periodogram, band, inside)
    band_otf = _band_mean(otf_power, band, inside)
    band_freq = _band_mean(radius, band, inside)
    noise_power = n_pixels * sigma[..., None] ** 2
    usable = (band_power > _MIN_BAND_SNR * noise_power) & (band_otf > _MIN_BAND_OTF_POWER)
    log_f = torch.where(usable, band_freq.clamp_min(1e-12).log(), 0.0)
    log_s = torch.where(
        usable, ((band_power - noise_power).clamp_min(1e-30) / band_otf.clamp_min(1e-30)).log(), 0.0
    )
    weight = usable.to(y.dtype)
    n_usable = weight.sum(-1)
    mean_f = (weight * log_f).sum(-1) / n_usable.clamp_min(1.0)
    mean_s = (weight * log_s).sum(-1) / n_usable.clamp_min(1.0)
    d_f = weight * (log_f - mean_f[..., None])
    slope = (d_f * (log_s - mean_s[..., None])).sum(-1) / d_f.square().sum(-1).clamp_min(1e-12)
    alpha = (-slope).clamp(*_ALPHA_RANGE)
    log_amplitude = torch.where(n_usable >= 2, mean_s + alpha * mean_f, -math.inf)
    grid_radius = _radial_frequency(*grid_shape, y)
    scene_inverse = grid_radius ** alpha[..., None, None] * torch.exp(-log_amplitude)[..., None, None]
    nsr = noise_power[..., None] * scene_inverse
    return torch.where(grid_radius > 0, nsr, 0.0)

def edge_taper(padded: Tensor, otf: Tensor, pad: tuple[int, int]) -> Tensor:
    """Blend the padding band of an image into its circularly blurred copy.

    FFT deconvolution assumes the blur is circular; a padded image violates that at the seam
    where its far edges wrap onto each other, and the inverse filter amplifies that mismatch
    into ringing that reaches deep into the image. Across the ``pad`` band the image fades
    (raised cosine) into ``circular_blur(padded)``, which obeys the circular model exactly,
    so the seam carries no unblurred edge (as MATLAB's ``edgetaper``). The original image
    region is left untouched.

    Args:
        padded: Images, shape (B, C, H', W'), padded by ``pad`` = (rows, cols) on each side.
        otf: Complex OTF for that grid, shape (C, H', W' // 2 + 1) or (H', W' // 2 + 1).
        pad: Padding (rows, cols) on each side, in pixels.

    Returns:
        Tapered images, shape (B, C, H', W'), same dtype and device.
    """
    blurred = torch.fft.irfft2(torch.fft.rfft2(padded) * otf, s=padded.shape[-2:])
    weight = torch.outer(
        _taper_1d(padded.shape[-2], pad[0], padded), _taper_1d(padded.shape[-1], pad[1], padded)
    )
    return weight * padded + (1.0 - weight) * blurred

def wiener_deconvolve(
    y: Tensor,
    psf: Tensor,
    balance: float | None = None,
    pad: bool = True,
    min_sigma: float = ADC_NOISE_SIGMA,
    sigma: Tensor | None = None,
) -> Tensor:
    """Wiener deconvolution of each channel with its own PSF, via FFT (unclamped).

    Args:
        y: Blurred images, shape (B, C, H, W), any real dtype and device.
        psf: Shape (C, K, K) (or (K, K), shared), centre at [K // 2, K // 2], channels sum to 1.
        balance: Constant NSR for every frequency (``skimage.restoration.wiener``'s
            ``balance`` with an identity regularizer); None estimates a per-image, per-channel,
            per-frequency NSR from ``y`` (noise MAD and a fitted power-law scene, module docs).
        pad: Reflect-pad by the PSF radius and taper the pad (``edge_taper``) before the FFT,
            crop after: less border ringing. False filters circularly, the exact inverse of an
            OTF product.
        min_sigma: Noise floor for the estimated NSR, in the units of ``y``.
        sigma: Noise standard deviation (B, C) when the caller estimated it better (e.g. on the
            raw Bayer lattice); None estimates it from ``y`` with ``estimate_noise_sigma``.

    Returns:
        Deconvolved images, shape (B, C, H, W), same dtype and device as ``y``, not clamped.
    """
    height, width = y.shape[-2:]
    psf = psf.to(device=y.device, dtype=y.dtype)
    # torch's reflect padding must be smaller than the image; tiny images get less padding.
    pad_h = min(psf.shape[-2] // 2, height - 1) if pad else 0
    pad_w = min(psf.shape[-1] // 2, width - 1) if pad else 0
    grid = (height + 2 * pad_h, width + 2 * pad_w)
    otf = psf_to_otf(psf, grid)[..., : grid[1] // 2 + 1]
    padded = y
    if pad:
        padded = F.pad(y, (pad_w, pad_w, pad_h, pad_h), mode="reflect")
        padded = edge_taper(padded, otf, (pad_h, pad_w))
    if balance is None:
        if sigma is None:
            sigma = estimate_noise_sigma(y, min_sigma)
        nsr = power_law_nsr(y, psf, sigma.to(y.dtype), grid)
    else:
        nsr = torch.as_tensor(balance, dtype=y.dtype, device=y.device)
    spectrum = otf.conj() * torch.fft.rfft2(padded) / (otf.abs() ** 2 + nsr)
    restored = torch.fft.irfft2(spectrum, s=grid)
    return restored[..., pad_h : pad_h + height, pad_w : pad_w + width]

def _radial_frequency(height: int, width: int, like: Tensor) -> Tensor:
    """|f| in cycles per pixel on an (height, width // 2 + 1) ``rfft2`` grid."""
    fy = torch.fft.fftfreq(height, dtype=like.dtype, device=like.device)
    fx = torch.fft.rfftfreq(width, dtype=like.dtype, device=like.device)
    return torch.sqrt(fy[:, None] ** 2 + fx[None, :] ** 2)

def _band_mean(values: Tensor, band: Tensor, inside: Tensor) -> Tensor:
    """Mean of ``values`` (..., H, W') over each frequency band -> (..., _N_BANDS)."""
    index = band[inside]
    flat = values.flatten(-2)[..., inside]
    sums = values.new_zeros(*values.shape[:-2], _N_BANDS).index_add_(-1, index, flat)
    counts = torch.bincount(index, minlength=_N_BANDS).to(values.dtype)
    return sums / counts.clamp_min(1.0)

def _taper_1d(length: int, pad: int, like: Tensor) -> Tensor:
    """1 on [pad, length - pad), raised cosine down to ~0 across the ``pad`` samples each side."""
    i = torch.arange(length, dtype=like.dtype, device=like.device)
    inward = torch.minimum(i + 1, length - i)  # 1 at either outer edge
    ramp = 0.5 - 0.5 * torch.cos(math.pi * inward / (pad + 1))
    return torch.where(inward > pad, 1.0, ramp)

def richardson_lucy_iterates(y: Tensor, psf: Tensor, max_iterations: int, pad: bool = True
                             ) -> Iterator[tuple[int, Tensor]]:
    """Yield ``(k, estimate_k)`` for k = 1..max_iterations of Richardson-Lucy.

    Args:
        y: Blurred non-negative images (B, C, H, W), any scale.
        psf: (C, K, K) or (K, K), centred at [K // 2, K // 2], channels sum to 1.
        max_iterations: Last iteration to yield.
        pad: Reflect-pad by the PSF radius with an edge taper (module docs); False deconvolves
            circularly.

    Yields:
        k and the estimate after k iterations, (B, C, H, W), unclamped, same dtype as ``y``.
    """
    height, width = y.shape[-2:]
    psf = psf.to(device=y.device, dtype=y.dtype)
    top, bottom = _padding(height, psf.shape[-2] // 2) if pad else (0, 0)
    left, right = _padding(width, psf.shape[-1] // 2) if pad else (0, 0)
    grid = (height + top + bottom, width + left + right)
    otf = psf_to_otf(psf, grid)[..., : grid[1] // 2 + 1]
    data = y
    if pad:
        data = edge_taper(F.pad(y, (left, right, top, bottom), mode="reflect"), otf, (top, left))
    estimate = torch.full_like(data, 0.5)
    for k in range(1, max_iterations + 1):
        reblurred = torch.fft.irfft2(torch.fft.rfft2(estimate) * otf, s=grid)
        ratio = data / (reblurred.clamp_min(0.0) + _EPS)
        estimate = estimate * torch.fft.irfft2(torch.fft.rfft2(ratio) * otf.conj(), s=grid)
        yield k, estimate[..., top : top + height, left : left + width]

def _padding(size: int, radius: int) -> tuple[int, int]:
    """(before, after) padding of at least ``radius`` (less than ``size``) that makes the padded
    length FFT-friendly: 1024 + 2 x 19 = 1062 = 2 x 3^2 x 59 costs several times 1080."""
    radius = min(radius, size - 1)
    extra = min(next_fast_len(size + 2 * radius, real=True) - size, 2 * (size - 1))
    return extra // 2, extra - extra // 2

def richardson_lucy(y: Tensor, psf: Tensor, iterations: int) -> Tensor:
    result = y
    for _, result in richardson_lucy_iterates(y, psf, iterations):
        pass
    return result

def restore_wiener(sensor: Tensor, psf: Tensor, gain: Tensor) -> Tensor:
    """``WienerKnownPSF.restore`` before the speed work."""
    gain = gain.to(device=sensor.device, dtype=sensor.dtype)
    deblurred = wiener_deconvolve(sensor, psf, sigma=bayer_noise_sigma(sensor))
    return (deblurred / gain[:, None, None]).clamp(0.0, 1.0)

def restore_richardson_lucy(sensor: Tensor, psf: Tensor, gain: Tensor, iterations: int) -> Tensor:
    """``RichardsonLucyKnownPSF.restore`` before the speed work."""
    divided = sensor / gain.to(device=sensor.device, dtype=sensor.dtype)[:, None, None]
    return richardson_lucy(divided, psf, iterations).clamp(0.0, 1.0)
