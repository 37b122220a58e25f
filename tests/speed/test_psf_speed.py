"""RGB PSF speed: the suite's PSF with its gradient against prysm's forward-only RGB PSF.

Run with `pytest tests/speed/test_psf_speed.py --benchmark-only`. Target: the PSF
with its gradient through the mask coefficients takes no longer than prysm's forward-only RGB PSF at
the same pupil grid and the same sensor samples, ratio <= 1 in one run.

prysm has no pixel integration, so its pixel PSF is its intensity at the midpoints of s x s cells
per pixel, summed (K*s samples per side at pitch / s): s = 3, the suite's earlier rule (4.7 % from the
closed form, where the suite's exact integration is within 0.1 %), the cheapest pixel PSF prysm can
give at that grid. Every library runs at its default thread count; prysm's point-sampled K x K PSF
(no pixel integration at all) is timed too, for information only.

The contenders take turns in blocks (fastest call of all blocks counts), each block after a pause
and one untimed call: after a call, numpy's OpenBLAS keeps a worker thread spinning for about
2^28 cycles (~0.1 s, its THREAD_TIMEOUT), which on 2 cores takes one from torch's OpenMP threads,
so a torch call timed right after a prysm call ran 1.3-8x slower than after a pause, while a prysm
call after a torch call was not slowed (OpenMP's workers sleep within a millisecond; measured
2026-11-24, load 8-17). Strict alternation therefore timed the interference, against the suite;
blocks still share the machine's load between both.
"""

from __future__ import annotations

import time
import warnings

import numpy as np
import pytest
import torch

import lenses
from lenses.builtin import SPEC_DIR
from lenses.spec import load_spec

with warnings.catch_warnings():  # prysm 0.21 imports pkg_resources, which warns on import
    warnings.simplefilter("ignore")
    propagation = pytest.importorskip(
        "prysm.propagation", reason="prysm is not installed (pip install -e '.[test]'); it is the speed reference")

BLOCKS = 5
CALLS_PER_BLOCK = 3
SETTLE_S = 0.3  # > OpenBLAS's idle spin (2^28 cycles)
SUBSAMPLES = 3


def _lens(name: str) -> lenses.Lens:
    """The co-design start (a trainable mask), or a registered fixed lens made trainable in place:
    the PSF is timed with the gradient a trainable mask needs."""
    if name == "codesign":
        return lenses.Lens(load_spec(SPEC_DIR / "codesign.toml"))
    lens = lenses.load(name)
    lens.coefficients_um.requires_grad_(True)
    return lens


def prysm_rgb_psf(lens: lenses.Lens, subsamples: int) -> np.ndarray:
    """prysm's PSF of the lens's pupil (same N x N grid, phase and aperture), (3, K, K), each channel
    summing to 1: intensity at K*s points per side at pitch / s, summed over each pixel's s x s."""
    model = lens.pupil
    c = model.constants
    k = lens.geometry.psf_size_px
    phase = model.pupil_phase(lens.coefficients_um.detach()).numpy()
    aperture = model.aperture.numpy()
    out = []
    for ch, wavelength_mm in enumerate(c.wavelength_mm):
        field = propagation.focus_fixed_sampling(
            aperture * np.exp(1j * phase[ch]), model.pupil_dx_mm, c.sensor_distance_mm, wavelength_mm * 1e3,
            lens.spec.sensor.pixel_pitch_um / subsamples, k * subsamples)
        intensity = (field.real**2 + field.imag**2).reshape(k, subsamples, k, subsamples).sum(axis=(1, 3))
        out.append(intensity / intensity.sum())
    return np.stack(out)


def test_prysm_reference_computes_the_same_sampled_psf():
    """The timed prysm code evaluates the same pupil on the same sensor samples as the suite's
    point-sampled intensity (so the race is between equal computations)."""
    lens = _lens("codesign")
    coeffs = torch.tensor([0.0, 0.2, -0.1, 0.5, -0.3, 0.4])
    with torch.no_grad():
        lens.coefficients_um.copy_(coeffs)
    k, s = lens.geometry.psf_size_px, SUBSAMPLES
    ours = lens.pupil.sampled_intensity(coeffs, s).reshape(3, k, s, k, s).sum(dim=(2, 4))
    ours = (ours / ours.sum(dim=(1, 2), keepdim=True)).numpy()
    np.testing.assert_allclose(prysm_rgb_psf(lens, s), ours, rtol=0, atol=1e-6 * ours.max())


@pytest.mark.parametrize("name", ["codesign", "ideal"])
def test_psf_with_gradient_vs_prysm_forward(benchmark, name):
    lens = _lens(name)
    weights = torch.rand(3, lens.geometry.psf_size_px, lens.geometry.psf_size_px,
                         generator=torch.Generator().manual_seed(0))

    def ours() -> None:
        lens.coefficients_um.grad = None
        (lens.psf() * weights).sum().backward()

    def prysm() -> None:
        prysm_rgb_psf(lens, SUBSAMPLES)

    ours_s, prysm_s, point_s = [], [], []
    for _ in range(BLOCKS):
        for fn, times in ((ours, ours_s), (prysm, prysm_s), (lambda: prysm_rgb_psf(lens, 1), point_s)):
            time.sleep(SETTLE_S)
            fn()
            for _ in range(CALLS_PER_BLOCK):
                t0 = time.perf_counter()
                fn()
                times.append(time.perf_counter() - t0)
    time.sleep(SETTLE_S)
    benchmark.pedantic(ours, rounds=BLOCKS * CALLS_PER_BLOCK, iterations=1, warmup_rounds=1)
    ratio = min(ours_s) / min(prysm_s)
    benchmark.extra_info.update({
        "pupil_samples": lens.geometry.pupil_samples, "psf_size_px": lens.geometry.psf_size_px,
        "ours_psf_grad_ms": 1e3 * min(ours_s), "prysm_forward_ms": 1e3 * min(prysm_s),
        "prysm_point_sampled_forward_ms": 1e3 * min(point_s), "ratio_ours_over_prysm": ratio,
        "torch_threads": torch.get_num_threads()})
    assert ratio <= 1.0, (f"PSF + gradient {1e3 * min(ours_s):.1f} ms vs prysm forward {1e3 * min(prysm_s):.1f} ms"
                          f" (ratio {ratio:.2f}) at N = {lens.geometry.pupil_samples}, K = {lens.geometry.psf_size_px}")
