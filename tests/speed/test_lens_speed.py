"""Lens speed (pytest-benchmark; run with `pytest tests/speed --benchmark-only`).

Targets on the 2-core CPU: the lens forward (PSF convolution + sensor) >= 25 images/s at
512 x 1024 in batches of 8, and faster than the forward before the speed work
(`lens_forward_before`, the code of 2026-11-22) in the same run. The equality of the two is an
ordinary test and runs by default. The PSF with its gradient is timed against prysm in
test_psf_speed.py.
"""

import time

import pytest
import torch

import lenses
from lenses.convolve import convolve_direct, convolve_fft
from lenses.optics import Geometry
from lenses.spec import parse_spec

import lens_forward_before

TARGET_IMAGES_PER_S = 25.0
ROUNDS = 5


def _before(lens: lenses.Lens, x: torch.Tensor, generator: torch.Generator) -> torch.Tensor:
    return lens_forward_before.forward(x, lens.psf(), lens.spec.sensor, lens.spec.optics.aperture_diameter_mm,
                                       generator)


@pytest.mark.parametrize("shape", [(2, 3, 64, 96), (1, 3, 37, 53)], ids=["even", "odd"])
@pytest.mark.parametrize("psf_size_px", [None, 9], ids=["fft-path", "direct-path"])
def test_forward_equals_the_code_before_the_speedup(shape, psf_size_px):
    """Same PSF, same noise draw: the faster forward gives the old output within 1e-5."""
    spec = parse_spec({"name": "t", "mask": {"zernike_um": [0.0, 0.1, -0.1, 0.3, 0.2, -0.2]}})
    lens = lenses.Lens(spec, None if psf_size_px is None else Geometry(pupil_samples=128, psf_size_px=psf_size_px))
    x = torch.rand(*shape, generator=torch.Generator().manual_seed(0))
    with torch.no_grad():
        new = lens(x, generator=torch.Generator().manual_seed(1))
        old = _before(lens, x, torch.Generator().manual_seed(1))
        lens(x, generator=torch.Generator().manual_seed(1))  # and again from the cached OTF
        cached = lens(x, generator=torch.Generator().manual_seed(1))
    torch.testing.assert_close(new, old, atol=1e-5, rtol=0)
    torch.testing.assert_close(cached, new, atol=0, rtol=0)


@pytest.mark.parametrize("name", ["ideal", "defocus"])
def test_lens_forward_batch8_512x1024(benchmark, name):
    lens = lenses.load(name)
    x = torch.rand(8, 3, 512, 1024)

    def new() -> None:
        lens(x, generator=torch.Generator().manual_seed(0))

    def before() -> None:
        _before(lens, x, torch.Generator().manual_seed(0))

    with torch.no_grad():
        new()
        before()
        new_s, before_s = [], []
        for _ in range(ROUNDS):  # alternate, so that both see the same load on the machine
            for fn, times in ((before, before_s), (new, new_s)):
                t0 = time.perf_counter()
                fn()
                times.append(time.perf_counter() - t0)
        benchmark.pedantic(new, rounds=ROUNDS, iterations=1, warmup_rounds=0)
    images_per_s = 8 / min(new_s)
    speedup = min(before_s) / min(new_s)
    benchmark.extra_info.update({"images_per_s": images_per_s, "before_images_per_s": 8 / min(before_s),
                                 "speedup": speedup, "psf_size_px": lens.geometry.psf_size_px,
                                 "torch_threads": torch.get_num_threads()})
    assert speedup > 1.0, f"new forward {8 / min(new_s):.1f} images/s, before {8 / min(before_s):.1f}"
    assert images_per_s >= TARGET_IMAGES_PER_S, (
        f"{images_per_s:.1f} images/s < {TARGET_IMAGES_PER_S} at 512x1024 (batch 8, {torch.get_num_threads()}"
        f" threads; {speedup:.2f}x the code before)")


@pytest.mark.parametrize("k", [7, 11, 15, 21, 35])
@pytest.mark.parametrize("method", ["direct", "fft"])
def test_convolution_crossover(benchmark, k, method):
    x = torch.rand(8, 3, 512, 1024)
    psf = torch.rand(3, k, k)
    fn = convolve_direct if method == "direct" else convolve_fft
    with torch.no_grad():
        benchmark.pedantic(lambda: fn(x, psf), rounds=3, iterations=1, warmup_rounds=1)
