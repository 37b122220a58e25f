"""``richardson-lucy-known-psf``: the attacker measured the PSF and gain; Richardson-Lucy.

Richardson-Lucy (Richardson 1972, Lucy 1974) is the maximum-likelihood deconvolution under
Poisson noise, the sensor's dominant noise: starting from a flat 0.5 image, each iteration
multiplies the estimate by the back-projected ratio of the data to the re-blurred estimate,
``u <- u * (H^T (y / (H u)))``. It keeps the estimate non-negative, but amplifies noise as
iterations go on, so the iteration count is the regulariser. It is CHOSEN on the TRAIN split:
``fit`` runs the ladder ``ITERATION_LADDER`` on a few ``ctx.train_pairs`` batches and keeps the
count with the best mean PSNR (recorded in ``describe()``).

Implementation: per-channel real-FFT convolutions (``attacks.backends.real_fft``: ``torch.fft``, or scipy's
pocketfft on the CPU where that is faster), the OTF computed once per image size and reused across batches,
a few images at a time so that every temporary stays small. As in ``wiener-known-psf``
(whose helpers it reuses) the sensor image is first divided by the per-channel gain, then
reflect-padded by the PSF radius with the pad tapered into its circularly blurred copy
(``edge_taper``), so the circular FFT model holds at the seam; the result is cropped and
clamped to [0, 1]. In the interior it equals ``skimage.restoration.richardson_lucy``
(tests/attacks/restorers/test_richardson_lucy.py).
"""

from __future__ import annotations

import math
from collections.abc import Iterator
from typing import Any, ClassVar

import torch
import torch.nn.functional as F
from scipy.fft import next_fast_len
from torch import Tensor

from attacks.backends import real_fft
from attacks.base import FitContext, FitReport, Restorer, ThreatModel
from attacks.backends.real_fft import OtfCache, circular_filter, image_chunks
from attacks.backends.wiener import edge_taper

__all__ = ["ITERATION_LADDER", "RichardsonLucyKnownPSF", "richardson_lucy", "richardson_lucy_iterates"]

ITERATION_LADDER: tuple[int, ...] = (1, 2, 3, 5, 8, 13, 20, 30, 50, 80)
"""Iteration counts tried by ``fit`` (roughly geometric: PSNR changes slowly in log k)."""

_FIT_BATCHES = 2
# Where the re-blurred estimate H u is below this many machine epsilons of the image's maximum, the
# ratio y / (H u) is set to 0 (skimage's ``filter_epsilon``): below it H u is FFT rounding, not signal.
# A fixed 1e-12 guard (skimage's default in float64) is not enough in float32: with a delta PSF
# (``sensor-only``), padding values of ~1e-8 over rounding of ~1e-7 gave ratios of 1e4 that grew to
# inf by iteration 8-9 (a 512 x 832 plate window of the quick run came back all NaN).
_FLOOR_EPS = 16


def richardson_lucy_iterates(y: Tensor, psf: Tensor | OtfCache, max_iterations: int, pad: bool = True
                             ) -> Iterator[tuple[int, Tensor]]:
    """Yield ``(k, estimate_k)`` for k = 1..max_iterations of Richardson-Lucy.

    Args:
        y: Blurred non-negative images (B, C, H, W), any scale.
        psf: (C, K, K) or (K, K), centred at [K // 2, K // 2], channels sum to 1; or its
            ``OtfCache``, which keeps the OTF of each grid size for the next call.
        max_iterations: Last iteration to yield.
        pad: Reflect-pad by the PSF radius with an edge taper (module docs); False deconvolves
            circularly.

    Yields:
        k and the estimate after k iterations, (B, C, H, W), unclamped, same dtype as ``y``.
    """
    otfs = psf if isinstance(psf, OtfCache) else OtfCache(psf)
    height, width = y.shape[-2:]
    top, bottom, left, right = _padding_of(y, otfs.psf, pad)
    grid = (height + top + bottom, width + left + right)
    otf = otfs(grid, y.dtype, y.device)
    otf_conj = otf.conj().resolve_conj()  # materialised once, not in every product
    data = y
    if pad:
        data = edge_taper(F.pad(y, (left, right, top, bottom), mode="reflect"), otf, (top, left))
    estimate = torch.full_like(data, 0.5)
    floor = _FLOOR_EPS * torch.finfo(data.dtype).eps * data.abs().amax(dim=(-3, -2, -1), keepdim=True)
    zero = data.new_zeros(())
    for k in range(1, max_iterations + 1):
        reblurred = circular_filter(estimate, otf)
        ratio = torch.where(reblurred > floor, data / reblurred, zero)
        estimate = estimate * circular_filter(ratio, otf_conj)
        yield k, estimate[..., top : top + height, left : left + width]


def _padding_of(y: Tensor, psf: Tensor, pad: bool) -> tuple[int, int, int, int]:
    """(top, bottom, left, right) padding of images ``y`` for ``psf`` (none when not ``pad``)."""
    if not pad:
        return 0, 0, 0, 0
    return (*_padding(y.shape[-2], psf.shape[-2] // 2), *_padding(y.shape[-1], psf.shape[-1] // 2))


def _padding(size: int, radius: int) -> tuple[int, int]:
    """(before, after) padding of at least ``radius`` (less than ``size``) that makes the padded
    length FFT-friendly: 1024 + 2 x 19 = 1062 = 2 x 3^2 x 59 costs several times 1080."""
    radius = min(radius, size - 1)
    extra = min(next_fast_len(size + 2 * radius, real=True) - size, 2 * (size - 1))
    return extra // 2, extra - extra // 2


def _chunks(y: Tensor, psf: Tensor, pad: bool) -> Iterator[slice]:
    """Slices of the batch ``y`` whose padded spectra fit ``attacks.backends.real_fft.ITERATIVE_CHUNK_BYTES``."""
    top, bottom, left, right = _padding_of(y, psf, pad)
    complex_bytes = 2 * y.element_size()
    per_image = y.shape[-3] * (y.shape[-2] + top + bottom) * ((y.shape[-1] + left + right) // 2 + 1) * complex_bytes
    return image_chunks(y.shape[0], per_image, real_fft.ITERATIVE_CHUNK_BYTES)


def richardson_lucy(y: Tensor, psf: Tensor | OtfCache, iterations: int, pad: bool = True) -> Tensor:
    """Richardson-Lucy deconvolution after ``iterations`` iterations (``richardson_lucy_iterates``).

    Images are deconvolved a few at a time (``attacks.backends.real_fft.image_chunks``); each image's
    result is independent of the others in its batch.

    Returns:
        Estimate (B, C, H, W), unclamped; ``y`` itself when ``iterations`` is 0.
    """
    if iterations == 0:
        return y
    otfs = psf if isinstance(psf, OtfCache) else OtfCache(psf)
    results = []
    for chunk in _chunks(y, otfs.psf, pad):
        for _, result in richardson_lucy_iterates(y[chunk], otfs, iterations, pad):
            pass
        results.append(result)
    return torch.cat(results)


def _psnr_db(x: Tensor, ref: Tensor) -> Tensor:
    """PSNR per image (B,) in dB, peak 1."""
    mse = (x - ref).pow(2).flatten(1).mean(dim=1)
    return 10.0 * torch.log10(1.0 / mse.clamp_min(1e-12))


class RichardsonLucyKnownPSF(Restorer):
    """Gain division, then Richardson-Lucy with the measured PSF; iterations chosen on TRAIN.

    Args:
        iterations: Fixed iteration count; None (default) chooses it in ``fit`` from
            ``ITERATION_LADDER`` on ``ctx.train_pairs``.

    Attributes:
        ladder_psnr_db: After a choosing ``fit``: mean TRAIN PSNR (dB) per tried count.
    """

    name: ClassVar[str] = "richardson-lucy-known-psf"
    threat_model: ClassVar[ThreatModel] = ThreatModel.LENS_ACCESS
    requires: ClassVar[frozenset[str]] = frozenset({"lens"})

    def __init__(self, iterations: int | None = None) -> None:
        if iterations is not None and iterations < 1:
            raise ValueError(f"{self.name}: iterations must be >= 1 or None (choose on TRAIN), got {iterations}")
        self._fixed = iterations
        self.iterations = iterations
        self.ladder_psnr_db: dict[int, float] = {}
        self._psf: OtfCache | None = None
        self._gain: Tensor | None = None

    def fit(self, ctx: FitContext) -> FitReport:
        """Measure the PSF and gain; choose the iteration count on ``ctx.train_pairs``."""
        assert ctx.lens is not None  # checked by `requires`
        self._psf = OtfCache(ctx.lens.psf().detach())
        self._gain = ctx.lens.gain().detach()
        if self._fixed is not None:
            return FitReport()
        if ctx.train_pairs is None:
            raise ValueError(f"{self.name}: choosing the iteration count needs FitContext.train_pairs; "
                             "or pass iterations=N")
        totals = dict.fromkeys(ITERATION_LADDER, 0.0)
        n_images = 0
        for batch, (sensor, sharp) in enumerate(ctx.train_pairs()):
            if batch == _FIT_BATCHES:
                break
            divided = self._divide_gain(sensor)
            with torch.no_grad():
                for chunk in _chunks(divided, self._psf.psf, True):
                    for k, estimate in richardson_lucy_iterates(divided[chunk], self._psf, ITERATION_LADDER[-1]):
                        if k in totals:
                            totals[k] += float(_psnr_db(estimate.clamp(0.0, 1.0), sharp[chunk]).sum())
            n_images += sensor.shape[0]
        self.ladder_psnr_db = {k: total / max(n_images, 1) for k, total in totals.items()}
        self.iterations = max(self.ladder_psnr_db, key=lambda k: self.ladder_psnr_db[k])
        return FitReport()

    def _divide_gain(self, sensor: Tensor) -> Tensor:
        assert self._gain is not None
        return sensor / self._gain.to(device=sensor.device, dtype=sensor.dtype)[:, None, None]

    def restore(self, sensor: Tensor) -> Tensor:
        """Scene estimate: (B, 3, H, W) in [0, 1] -> (B, 3, H, W) in [0, 1]."""
        if self._psf is None or self.iterations is None:
            raise RuntimeError(f"{self.name}: call fit(ctx) before restore()")
        return richardson_lucy(self._divide_gain(sensor), self._psf, self.iterations).clamp(0.0, 1.0)

    def describe(self) -> dict[str, Any]:
        """Configuration: the iteration count, how it was chosen, and the ladder's TRAIN PSNRs."""
        chosen_by = "fixed" if self._fixed is not None else "best mean PSNR on TRAIN pairs"
        ladder = {str(k): round(v, 3) for k, v in self.ladder_psnr_db.items() if math.isfinite(v)}
        return {**super().describe(), "iterations": self.iterations, "chosen_by": chosen_by,
                "ladder_psnr_db": ladder, "padding": "reflect-psf-radius+edge-taper"}
