"""Image-restoration metrics computed by the runner, identically for every attacker.

PSNR and SSIM follow scikit-image's definitions (`skimage.metrics.peak_signal_noise_ratio` and
`structural_similarity(..., gaussian_weights=True, sigma=1.5, use_sample_covariance=False,
data_range=1, channel_axis=...)`, i.e. Wang et al. 2004): PSNR in torch, SSIM with
OpenCV's separable filter.
"""

from __future__ import annotations

from concurrent.futures import ThreadPoolExecutor

import cv2
import numpy as np
import torch

_SIGMA = 1.5
_RADIUS = int(3.5 * _SIGMA + 0.5)  # scikit-image's gaussian truncation (truncate=3.5): 11 taps


def psnr(x: torch.Tensor, ref: torch.Tensor, data_range: float = 1.0) -> torch.Tensor:
    """PSNR in dB per image of (B,C,H,W) tensors; inf where identical.

    One image at a time: the float64 differences of a chunk of 8 quick scenes (three 100 MB
    temporaries) once set a quick run's resident peak (docs/history.md)."""
    if x.shape[0] == 0:
        return torch.zeros(0, dtype=torch.float64, device=x.device)
    mse = torch.stack([((a.double() - b.double()) ** 2).mean() for a, b in zip(x, ref)])
    return 10 * torch.log10(data_range**2 / mse)


def _gaussian_kernel() -> np.ndarray:
    """The 11-tap Gaussian (sigma 1.5) scikit-image uses, normalised, float64 (11, 1)."""
    t = np.arange(-_RADIUS, _RADIUS + 1, dtype=np.float64)
    w = np.exp(-0.5 * (t / _SIGMA) ** 2)
    return (w / w.sum())[:, None]


def ssim(x: torch.Tensor, ref: torch.Tensor, data_range: float = 1.0) -> torch.Tensor:
    """Mean SSIM per image of (B,C,H,W) tensors (channels averaged), as scikit-image computes it.

    Each of the five local moments is one separable OpenCV filter in float64, averaged over the
    region scikit-image keeps (the border of the filter's radius is cropped, so the border mode
    never enters). OpenCV's vectorised filter runs many times faster than torch's grouped float64
    conv2d (docs/modelling.md, "Speed of the evaluation"; tests/speed/test_ssim_speed.py); the values
    agree to 1e-15.
    """
    if x.shape != ref.shape or x.dim() != 4:
        raise ValueError(f"SSIM needs two (B,C,H,W) tensors of one shape, got {tuple(x.shape)} and {tuple(ref.shape)}")
    if min(x.shape[-2:]) < 2 * _RADIUS + 1:
        raise ValueError(f"SSIM needs images of at least {2 * _RADIUS + 1} px per side, got {tuple(x.shape[-2:])}")
    w = _gaussian_kernel()
    c1, c2 = (0.01 * data_range) ** 2, (0.03 * data_range) ** 2
    inner = (slice(_RADIUS, -_RADIUS), slice(_RADIUS, -_RADIUS))

    def blur(a: np.ndarray) -> np.ndarray:
        return cv2.sepFilter2D(a, cv2.CV_64F, w, w, borderType=cv2.BORDER_REFLECT)[inner]

    xs, rs = x.detach().cpu(), ref.detach().cpu()

    def channel(index: tuple[int, ...]) -> float:
        # float64 one channel image at a time (4 MB at 512 x 1024), not the whole batch at once.
        a, b = xs[index].double().numpy(), rs[index].double().numpy()
        mu_a, mu_b = blur(a), blur(b)
        saa = blur(a * a) - mu_a**2
        sbb = blur(b * b) - mu_b**2
        sab = blur(a * b) - mu_a * mu_b
        s = ((2 * mu_a * mu_b + c1) * (2 * sab + c2)) / ((mu_a**2 + mu_b**2 + c1) * (saa + sbb + c2))
        return float(s.mean())

    # OpenCV's filter and NumPy's arithmetic release the GIL and run one thread each, so channel
    # images go to torch's thread count of threads (faster on 2 cores: docs/modelling.md, "Restorer
    # inference"; the same arithmetic per channel, so the same values bit for bit).
    with ThreadPoolExecutor(max(1, torch.get_num_threads())) as pool:
        values = list(pool.map(channel, np.ndindex(*x.shape[:2])))
    out = np.array(values, dtype=np.float64).reshape(x.shape[:2])
    return torch.from_numpy(out.mean(axis=1))


def finite_mean(values: torch.Tensor) -> float:
    """Mean of per-image values, as a float. +inf (the PSNR of an exact copy) stays inf; NaN (an
    output that is not a number) is never scored: ValueError."""
    v = values.double()
    if bool(torch.isnan(v).any()):
        raise ValueError(f"{int(torch.isnan(v).sum())} of {v.numel()} per-image values are NaN; "
                         "a non-finite output is not scored")
    return float(v.mean())
