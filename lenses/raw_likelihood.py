"""The sensor's raw electrons as a likelihood: what an ideal observer of the lens computes.

Model (exactly `lenses.sensor.Sensor` before its clip, ADC and demosaic): the raw RGGB electrons of
pixel p in frame t are y_pt = mu_p + sqrt(mu_p + read^2) eps_pt, eps_pt ~ N(0, 1) independent over
pixels and frames, with mu = mosaic(e_c (h_c * x_c)) the mean electrons of scene radiance x through
the PSF h (e_c = electrons per unit radiance). The sensor image is a deterministic function of the
y_pt (full-well clip, 10-bit rounding and bilinear demosaic, which keeps each raw value at its own
site), so by the data-processing inequality any decision made from sensor images can also be made
from the y_pt: an observer that decides optimally from the y_pt is at least as accurate as any
attacker of the sensor images. Dropping clip and ADC therefore keeps every ceiling an upper bound
(their loss is small on a plate: the 10-bit step is 9.8 e-, i.e. 2.8 e- rms, against >= 18 e- of
shot + read noise on the darkest plate ink).

For T frames of a static scene, (s1_p, s2_p) = (sum_t y_pt, sum_t y_pt^2) is sufficient for mu, and
    log p(y | mu) = sum_p -T/2 log(2 pi v_p) - (s2_p - 2 mu_p s1_p + T mu_p^2) / (2 v_p),  v_p = mu_p + read^2,
so drawing (s1, s2) directly (sample mean ~ N(mu, v / T), sum of squared deviations ~ v chi2_{T-1})
costs the same for 1 or 30 frames.
"""

from __future__ import annotations

import math

import numpy as np
import torch
from scipy.fft import next_fast_len

from lenses.sensor import bayer_masks


def raw_mean_electrons(patch: torch.Tensor, surround_radiance: float, psf: torch.Tensor,
                       electrons_per_unit: torch.Tensor, bayer_phase: tuple[int, int] = (0, 0)) -> torch.Tensor:
    """Mean raw electrons (N, h + 2r, w + 2r) of patches (N, 3, h, w) on a uniform surround, r = K // 2.

    The patch (scene radiance, linear, in [0, 1]) lies on an infinite surround of radiance
    `surround_radiance`; the result covers the patch and the r pixels around it that its light reaches
    through the (3, K, K) PSF (each channel summing to 1), beyond which only the surround is seen.
    Exact linear convolution through a zero-padded FFT (no wrap: the transform holds h + 2r rows).
    `bayer_phase` = (row, column) parity of the result's top-left pixel in the sensor's RGGB pattern
    ((0, 0): an R pixel). float64.
    """
    if patch.ndim != 4 or patch.shape[1] != 3:
        raise ValueError(f"patch must be (N, 3, h, w) radiance, got shape {tuple(patch.shape)}")
    k = psf.shape[-1]
    h, w = patch.shape[-2] + k - 1, patch.shape[-1] + k - 1
    # Transform sizes with small prime factors only (an awkward size costs several times more);
    # the extra rows and columns hold zeros of the linear convolution and are cut.
    fast = (next_fast_len(h, real=True), next_fast_len(w, real=True))
    spectrum = torch.fft.rfft2(patch.to(torch.float64) - surround_radiance, s=fast)
    irradiance = torch.fft.irfft2(spectrum * torch.fft.rfft2(psf.to(torch.float64), s=fast), s=fast)[..., :h, :w]
    irradiance = irradiance + surround_radiance * psf.to(torch.float64).sum((-2, -1))[:, None, None]
    return _raw_sites(irradiance, electrons_per_unit, _phase_masks(h, w, bayer_phase))


def _phase_masks(h: int, w: int, bayer_phase: tuple[int, int]) -> torch.Tensor:
    """(3, h, w) RGGB masks of a region whose top-left pixel has (row, column) parity `bayer_phase`."""
    oy, ox = bayer_phase[0] % 2, bayer_phase[1] % 2
    return bayer_masks(h + 1, w + 1, dtype=torch.float64)[:, oy:oy + h, ox:ox + w]


def _raw_sites(irradiance: torch.Tensor, electrons_per_unit: torch.Tensor, masks: torch.Tensor) -> torch.Tensor:
    """Mean raw electrons (N, h, w): each site's own channel of the irradiance (N, 3, h, w), in electrons."""
    electrons = irradiance.clamp(min=0.0) * electrons_per_unit.to(torch.float64)[:, None, None]
    return (electrons * masks).sum(1)


class BoxBlur:
    """Mean raw electrons over a box, of patches that fill the box on a black surround.

    ``BoxBlur(psf, e, (h, w), phase)(patch)`` equals ``raw_mean_electrons(patch, 0.0, psf, e, phase')``
    restricted to the patch's own pixels (``[r:r + h, r:r + w]``, phase' = phase - r), at a fraction of its
    cost, for every patch of one box (a reader scoring thousands of candidate plates at one box):

    - only the PSF's centre reaches from one pixel of the box to another, so the PSF is cut to
      (2h - 1) x (2w - 1) where it is larger;
    - the transform wraps: a circular convolution of n >= h + r rows (r the cut PSF's half height) is
      the linear one on the rows wanted (the wrapped light lands only on rows that are cut away);
    - the PSF's transform and the Bayer masks are computed once.

    `bayer_phase` = (row, column) parity of the box's top-left pixel in the sensor's RGGB pattern. float64.
    """

    def __init__(self, psf: torch.Tensor, electrons_per_unit: torch.Tensor, size_hw: tuple[int, int],
                 bayer_phase: tuple[int, int] = (0, 0)) -> None:
        h, w = size_hw
        r = psf.shape[-1] // 2
        ry, rx = min(r, h - 1), min(r, w - 1)  # the reach of one box pixel to another
        kernel = psf.to(torch.float64)[:, r - ry:r + ry + 1, r - rx:r + rx + 1]
        self.size, self.reach = (h, w), (ry, rx)
        self.fast = (next_fast_len(h + ry, real=True), next_fast_len(w + rx, real=True))
        # The kernel's centre at the origin of the circular transform: output pixel i is input pixel i blurred.
        padded = torch.zeros(3, *self.fast, dtype=torch.float64)
        padded[:, :2 * ry + 1, :2 * rx + 1] = kernel
        self.spectrum = torch.fft.rfft2(torch.roll(padded, (-ry, -rx), (-2, -1)))
        self.electrons_per_unit = electrons_per_unit
        self.masks = _phase_masks(h, w, bayer_phase)

    def __call__(self, patch: torch.Tensor) -> torch.Tensor:
        """(N, h, w) mean raw electrons of patches (N, 3, h, w) of radiance at the box."""
        h, w = self.size
        if tuple(patch.shape[-2:]) != (h, w):
            raise ValueError(f"patch must be (N, 3, {h}, {w}) for this box, got {tuple(patch.shape)}")
        irradiance = torch.fft.irfft2(torch.fft.rfft2(patch.to(torch.float64), s=self.fast) * self.spectrum,
                                      s=self.fast)[..., :h, :w]
        return _raw_sites(irradiance, self.electrons_per_unit, self.masks)


def draw_statistics(mean_e: torch.Tensor, read_noise_e: float, frames: int,
                    rng: np.random.Generator) -> tuple[torch.Tensor, torch.Tensor]:
    """Sufficient statistics (s1, s2), each (N, P) float64, of T = `frames` noisy frames of each row of mean_e (N, P).

    s1 = sum_t y_t and s2 = sum_t y_t^2 in electrons, drawn exactly from the module's noise model
    (numpy's generator: it draws chi-square variates directly, torch's do not take a generator; the
    variates are drawn in float32, whose rounding is far below the noise).
    """
    if frames < 1:
        raise ValueError(f"frames must be >= 1, got {frames}")
    mean = mean_e.detach().to(torch.float64).clamp(min=0.0).cpu().numpy()
    var = mean + read_noise_e**2
    ybar = mean + np.sqrt(var / frames) * rng.standard_normal(mean.shape, dtype=np.float32)
    if frames > 1:  # sum of squared deviations ~ var chi2_{T-1} = var 2 Gamma((T - 1) / 2)
        squared_deviations = var * 2.0 * rng.standard_gamma((frames - 1) / 2, mean.shape, dtype=np.float32)
    else:
        squared_deviations = np.zeros_like(ybar)
    return torch.from_numpy(frames * ybar), torch.from_numpy(squared_deviations + frames * ybar**2)


def log_likelihoods(s1: torch.Tensor, s2: torch.Tensor, frames: int, means_e: torch.Tensor,
                    read_noise_e: float) -> torch.Tensor:
    """log p(observation n | hypothesis a), (N, A), for statistics s1, s2 (N, P) and means_e (A, P).

    Exact for the module's noise model, up to one additive constant per observation (the same for
    every hypothesis, so posteriors and decisions are exact).
    """
    m = means_e.to(torch.float64).clamp(min=0.0)
    inv_v = 1.0 / (m + read_noise_e**2)
    const = -0.5 * frames * (torch.log(m + read_noise_e**2) + m * m * inv_v).sum(-1)
    return -0.5 * s2 @ inv_v.T + s1 @ (m * inv_v).T + const - 0.5 * frames * math.log(2 * math.pi) * m.shape[-1]
