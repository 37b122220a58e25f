"""Lens speed (pytest-benchmark; run with `pytest tests/benchmarks --benchmark-only`).

Targets on the 2-core CPU: PSF + backward < 50 ms; lens forward >= 10 images/s at 512 x 1024.
"""

import pytest
import torch

import lenses
from lenses.convolve import convolve_direct, convolve_fft
from lenses.spec import parse_spec


def test_psf_with_gradient(benchmark):
    lens = lenses.Lens(parse_spec({"name": "t", "mask": {"zernike_um": [0, 0.1, 0, 0.3, 0, 0],
                                                         "bounds_um": [[-1.0, 1.0]] * 6}}))

    def step():
        lens.coefficients_um.grad = None
        (lens.psf() ** 2).sum().backward()

    benchmark(step)
    benchmark.extra_info["psf_size_px"] = lens.geometry.psf_size_px


@pytest.mark.parametrize("name", ["ideal", "defocus"])
def test_lens_forward_batch8_512x1024(benchmark, name):
    lens = lenses.load(name)
    x = torch.rand(8, 3, 512, 1024)
    g = torch.Generator().manual_seed(0)
    with torch.no_grad():
        benchmark.pedantic(lambda: lens(x, generator=g), rounds=3, iterations=1, warmup_rounds=1)
    benchmark.extra_info["images_per_s"] = 8 / benchmark.stats.stats.mean


@pytest.mark.parametrize("k", [7, 11, 15, 21, 35])
@pytest.mark.parametrize("method", ["direct", "fft"])
def test_convolution_crossover(benchmark, k, method):
    x = torch.rand(8, 3, 512, 1024)
    psf = torch.rand(3, k, k)
    fn = convolve_direct if method == "direct" else convolve_fft
    with torch.no_grad():
        benchmark.pedantic(lambda: fn(x, psf), rounds=3, iterations=1, warmup_rounds=1)
