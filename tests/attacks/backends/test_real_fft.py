"""attacks.backends.real_fft: the scipy path (``CPU_FFT = "scipy"``) equals torch.fft, the OTF equals numpy's, chunks cover the batch."""

from __future__ import annotations

import numpy as np
import pytest
import torch

from attacks.backends import real_fft
from attacks.backends.real_fft import OtfCache, image_chunks, irfft2, rfft2, rfft_otf


@pytest.mark.parametrize("dtype,atol", [(torch.float32, 2e-4), (torch.float64, 1e-10)])
@pytest.mark.parametrize("shape", [(2, 3, 36, 50), (1, 3, 37, 53)], ids=["even", "odd"])
def test_scipy_transforms_equal_torch_fft(monkeypatch, dtype, atol, shape):
    monkeypatch.setattr(real_fft, "CPU_FFT", "scipy")
    x = torch.rand(*shape, generator=torch.Generator().manual_seed(0), dtype=dtype)
    spectrum = rfft2(x)
    assert spectrum.dtype == torch.fft.rfft2(x).dtype
    torch.testing.assert_close(spectrum, torch.fft.rfft2(x), atol=atol, rtol=0)
    # The conjugate's lazy bit must not reach numpy; odd widths need the explicit output size.
    back = irfft2(spectrum.conj().conj(), shape[-2:])
    torch.testing.assert_close(back, torch.fft.irfft2(torch.fft.rfft2(x), s=shape[-2:]), atol=atol, rtol=0)
    torch.testing.assert_close(back, x, atol=atol, rtol=0)


def test_gradients_flow_through_the_torch_path():
    x = torch.rand(1, 1, 8, 10, dtype=torch.float64, requires_grad=True)
    irfft2(rfft2(x) * 2.0, (8, 10)).sum().backward()
    torch.testing.assert_close(x.grad, torch.full_like(x, 2.0))


def test_otf_equals_numpy_fft_of_the_wrapped_psf():
    psf = torch.rand(3, 5, 7, generator=torch.Generator().manual_seed(1), dtype=torch.float64)
    shape = (12, 15)
    # Independent reference: place the PSF with its centre at (0, 0) by np.roll, full fft2.
    padded = np.zeros((3, *shape))
    padded[:, :5, :7] = psf.numpy()
    reference = np.fft.fft2(np.roll(padded, (-2, -3), axis=(1, 2)))[..., : shape[1] // 2 + 1]
    np.testing.assert_allclose(rfft_otf(psf, shape).numpy(), reference, atol=1e-12)


def test_a_psf_larger_than_the_grid_wraps_around():
    psf = torch.rand(9, 9, generator=torch.Generator().manual_seed(2), dtype=torch.float64)
    # Circular convolution on a 4 x 4 grid: the PSF's taps are summed modulo 4.
    wrapped = np.zeros((4, 4))
    for i in range(9):
        for j in range(9):
            wrapped[(i - 4) % 4, (j - 4) % 4] += psf[i, j].item()
    np.testing.assert_allclose(rfft_otf(psf, (4, 4)).numpy(), np.fft.rfft2(wrapped), atol=1e-12)


def test_otf_cache_computes_once_per_shape_and_dtype():
    psf = torch.rand(3, 5, 5, generator=torch.Generator().manual_seed(3))
    cache = OtfCache(psf)
    first = cache((16, 20), torch.float32, torch.device("cpu"))
    assert cache((16, 20), torch.float32, torch.device("cpu")) is first
    assert cache((16, 22), torch.float32, torch.device("cpu")).shape == (3, 16, 12)
    assert cache((16, 20), torch.float64, torch.device("cpu")).dtype == torch.complex128
    calls = []
    assert cache.derived("k", lambda: calls.append(1) or 5) == 5 and cache.derived("k", lambda: 6) == 5
    assert calls == [1]


def test_image_chunks_cover_the_batch_under_the_byte_bound(monkeypatch):
    monkeypatch.setattr(real_fft, "CHUNK_BYTES", 100)
    assert [(s.start, s.stop) for s in image_chunks(7, 30)] == [(0, 3), (3, 6), (6, 9)]
    assert len(list(image_chunks(3, 1000))) == 3  # never fewer than one image
    assert list(image_chunks(0, 30)) == []
    assert [(s.start, s.stop) for s in image_chunks(7, 30, max_bytes=60)] == [(0, 2), (2, 4), (4, 6), (6, 8)]


@pytest.mark.parametrize("cpu_fft", ["torch", "scipy"])
@pytest.mark.parametrize("dtype,atol", [(torch.float32, 2e-4), (torch.float64, 1e-10)])
def test_circular_filter_equals_the_torch_product(monkeypatch, dtype, atol, cpu_fft):
    monkeypatch.setattr(real_fft, "CPU_FFT", cpu_fft)
    g = torch.Generator().manual_seed(4)
    x = torch.rand(2, 3, 21, 30, generator=g, dtype=dtype)
    otf = rfft_otf(torch.rand(3, 5, 5, generator=g, dtype=dtype), (21, 30))
    for transfer in (otf, otf.conj()):  # a lazy conjugate view too
        reference = torch.fft.irfft2(torch.fft.rfft2(x) * transfer, s=(21, 30))
        torch.testing.assert_close(real_fft.circular_filter(x, transfer), reference, atol=atol, rtol=0)
