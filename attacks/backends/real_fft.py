"""Real 2-D FFTs for the deconvolution attackers, and the per-grid OTF cache they share.

Two implementations compute the same transforms to float rounding (tests/attacks/backends/test_real_fft.py):
``torch.fft``, and on the CPU without autograd ``scipy.fft`` (pocketfft) on the tensors' own memory,
with the filter's product taken in place by numpy. Which is faster is a property of the machine and
the versions, so ``CPU_FFT`` names the one used on the CPU; a GPU or a graph that needs gradients
always takes ``torch.fft``. It is ``torch.fft``, the faster on the machine measured last
(tests/speed/test_deconvolution_speed.py runs both paths alternating; docs/modelling.md, "Speed of
the evaluation"; the measurements per machine: docs/history.md).

``image_chunks`` splits a batch so that each chunk's spectrum stays under ``CHUNK_BYTES``: every
temporary of an iteration then stays below glibc's 32 MiB mmap ceiling and is reused from the
heap, instead of being mapped and page-faulted afresh on every operation (as in
``lenses.convolve.apply_otf``).
"""

from __future__ import annotations

from collections.abc import Callable, Hashable, Iterator
from typing import Any, TypeVar

import numpy as np
import scipy.fft
import torch
from torch import Tensor

__all__ = ["CHUNK_BYTES", "CPU_FFT", "ITERATIVE_CHUNK_BYTES", "OtfCache", "circular_filter", "image_chunks", "irfft2", "rfft2", "rfft_otf"]

T = TypeVar("T")

CHUNK_BYTES = 16 << 20
"""Largest spectrum (bytes) of one chunk of images from ``image_chunks``."""

ITERATIVE_CHUNK_BYTES = 4 << 20
"""Largest spectrum of one chunk for a filter applied many times to the same chunk (Richardson-Lucy's
iterations): those ran faster in chunks this small than at ``CHUNK_BYTES``, while a single filtering
(Wiener) gained nothing (docs/history.md). The outputs move by float rounding (at most 2e-6): a
batched FFT rounds differently from a single one."""


CPU_FFT = "torch"
"""The FFT used on the CPU without autograd: "torch" (``torch.fft``) or "scipy" (``scipy.fft``)."""


def _scipy_ok(x: Tensor) -> bool:
    return CPU_FFT == "scipy" and x.device.type == "cpu" and not (torch.is_grad_enabled() and x.requires_grad)


def rfft2(x: Tensor) -> Tensor:
    """``torch.fft.rfft2(x)`` over the last two axes: (..., H, W) real -> (..., H, W // 2 + 1) complex."""
    if not _scipy_ok(x) or x.dtype not in (torch.float32, torch.float64):
        return torch.fft.rfft2(x)
    return torch.from_numpy(scipy.fft.rfft2(x.detach().numpy(), workers=torch.get_num_threads()))


def irfft2(spectrum: Tensor, shape: tuple[int, int]) -> Tensor:
    """``torch.fft.irfft2(spectrum, s=shape)``: (..., H, W // 2 + 1) complex -> (..., H, W) real."""
    if not _scipy_ok(spectrum) or spectrum.dtype not in (torch.complex64, torch.complex128):
        return torch.fft.irfft2(spectrum, s=shape)
    return torch.from_numpy(scipy.fft.irfft2(spectrum.detach().resolve_conj().numpy(), s=shape, workers=torch.get_num_threads()))


def circular_filter(x: Tensor, transfer: Tensor) -> Tensor:
    """``irfft2(rfft2(x) * transfer)`` at x's size: x (..., H, W) real, circularly convolved with the
    filter whose ``rfft2``-layout transfer function is ``transfer`` (broadcastable to
    (..., H, W // 2 + 1), complex). On the scipy path the product is taken in place by numpy, which
    ran a complex64 product about 10x as fast as torch's (whose conjugate views cost 2x more again)."""
    shape = (x.shape[-2], x.shape[-1])
    if not (_scipy_ok(x) and _scipy_ok(transfer)) or x.dtype not in (torch.float32, torch.float64):
        return irfft2(rfft2(x) * transfer, shape)
    workers = torch.get_num_threads()
    spectrum = scipy.fft.rfft2(x.detach().numpy(), workers=workers)
    np.multiply(spectrum, transfer.detach().resolve_conj().numpy(), out=spectrum)
    return torch.from_numpy(scipy.fft.irfft2(spectrum, s=shape, workers=workers, overwrite_x=True))


def rfft_otf(psf: Tensor, shape: tuple[int, int]) -> Tensor:
    """Optical transfer function of a centred PSF on a ``shape`` grid, ``rfft2`` layout.

    Args:
        psf: Shape (..., K_h, K_w), centre at [K_h // 2, K_w // 2], real.
        shape: (H, W) of the grid; a PSF larger than the grid wraps around (summed), which is
            the exact circular operator.

    Returns:
        Complex OTF (..., H, W // 2 + 1), DC at [0, 0]: the first W // 2 + 1 columns of the
        ``fft2`` of the wrapped PSF.
    """
    k_h, k_w = psf.shape[-2:]
    height, width = shape
    rows = (torch.arange(k_h, device=psf.device) - k_h // 2) % height
    cols = (torch.arange(k_w, device=psf.device) - k_w // 2) % width
    flat_index = (rows[:, None] * width + cols[None, :]).reshape(-1)
    grid = psf.new_zeros(*psf.shape[:-2], height * width)
    grid.index_add_(-1, flat_index, psf.reshape(*psf.shape[:-2], k_h * k_w))
    return rfft2(grid.reshape(*psf.shape[:-2], height, width))


class OtfCache:
    """The ``rfft_otf`` of one PSF per (grid shape, dtype, device), computed on first use.

    A restorer sees the same few shapes again and again (the 512 x 1024 scenes, the plate windows
    grouped by size), so the transform of the PSF is done once per shape, not once per batch.

    Args:
        psf: (C, K, K) or (K, K), centred, real; never modified.
    """

    def __init__(self, psf: Tensor) -> None:
        self.psf = psf.detach()
        self._otfs: dict[tuple[tuple[int, int], torch.dtype, torch.device], Tensor] = {}
        self._derived: dict[Hashable, Any] = {}

    def __call__(self, shape: tuple[int, int], dtype: torch.dtype, device: torch.device) -> Tensor:
        """OTF (C, H, W // 2 + 1) (or (H, W // 2 + 1)) for an (H, W) grid of real ``dtype`` on ``device``."""
        grid = (int(shape[0]), int(shape[1]))
        key = (grid, dtype, torch.device(device))
        if key not in self._otfs:
            self._otfs[key] = rfft_otf(self.psf.to(device=device, dtype=dtype), grid)
        return self._otfs[key]

    def derived(self, key: Hashable, compute: Callable[[], T]) -> T:
        """A value derived from this PSF's OTFs (e.g. its mean power per frequency band of one
        image size), computed by ``compute`` on the first call with ``key`` and kept."""
        if key not in self._derived:
            self._derived[key] = compute()
        return self._derived[key]  # type: ignore[no-any-return]


def image_chunks(n_images: int, bytes_per_image: int, max_bytes: int | None = None) -> Iterator[slice]:
    """Consecutive slices of ``range(n_images)`` with at most ``max_bytes`` (default ``CHUNK_BYTES``) per
    slice (at least one image)."""
    step = max(1, (CHUNK_BYTES if max_bytes is None else max_bytes) // max(1, bytes_per_image))
    for start in range(0, n_images, step):
        yield slice(start, start + step)
