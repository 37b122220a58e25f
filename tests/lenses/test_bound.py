"""The privacy bound against closed forms, a brute-force reference, and its monotonicity and gradient."""

import math

import numpy as np
import pytest
import torch
from scipy import integrate, signal

from lenses import Lens
from lenses.bound import (ASSUMPTIONS, PlateSpectrum, bits_per_pixel, bound_curve, bound_row, certified_width,
                          fano_ceiling, noise_to_signal, plate_bits, plate_bits_per_channel)
from lenses.spec import parse_spec

ENTROPY = 28.77  # LLDDDLL


def flat_spectrum(density: float = 1e-3, aspect: float = 4.0, radiance: float = 0.5) -> PlateSpectrum:
    """D constant everywhere (the tail with exponent 0 continues the table)."""
    table = np.full((3, 2 * 4 + 1, 2 * 16 + 1), density)
    return PlateSpectrum(table, aspect, (density,) * 3, 0.0, (radiance,) * 3)


def smooth_spectrum(aspect: float = 4.7) -> PlateSpectrum:
    """A plate-like falling spectrum D = A / (1 + |nu|^2)^1.5."""
    ny, nx = 7, 32
    vy = (np.arange(2 * ny + 1) - ny)[:, None] * aspect
    vx = (np.arange(2 * nx + 1) - nx)[None, :]
    d = 0.05 / (1 + vy**2 + vx**2) ** 1.5
    return PlateSpectrum(np.stack([d, d, 0.8 * d]), aspect, (0.05, 0.05, 0.04), 3.0, (0.55, 0.55, 0.5))


def gaussian_psf(sigma_px: float, k: int = 31) -> torch.Tensor:
    r = torch.arange(k, dtype=torch.float64) - k // 2
    g = torch.exp(-(r[:, None] ** 2 + r[None, :] ** 2) / (2 * sigma_px**2))
    return (g / g.sum()).expand(3, k, k).clone()


def lens(focus_m: float = 10.0, **sensor) -> Lens:
    return Lens(parse_spec({"name": "t", "optics": {"focus_distance_m": focus_m},
                            "mask": {"zernike_um": [0.0] * 6}, "sensor": sensor}))


def test_rate_matches_polar_integral_for_gaussian_psf_and_flat_spectrum():
    sigma, width, density = 1.5, 16, 2e-3
    nsr = torch.full((3,), 1e-3, dtype=torch.float64)
    a = width**2 * density / 1e-3  # SNR at f = 0

    def integrand(r, theta):
        return r * 0.5 * math.log2(1 + a * math.exp(-4 * math.pi**2 * sigma**2 * r**2))

    # The Nyquist square is 8 copies of the triangle 0 <= theta <= pi/4, r <= 1 / (2 cos theta).
    reference, _ = integrate.dblquad(integrand, 0, math.pi / 4, 0, lambda t: 0.5 / math.cos(t), epsabs=1e-10)
    got = bits_per_pixel(gaussian_psf(sigma), flat_spectrum(density), width, nsr)
    np.testing.assert_allclose(got.numpy(), 8 * reference, rtol=1e-3)


def test_block_matches_explicit_convolution_matrix():
    """Flat spectrum: content covariance sigma^2 I, so B = 1/2 log2 det(I + sigma^2 H^T H / nsr) exactly."""
    rng = np.random.default_rng(0)
    psf = rng.random((3, 5, 5))
    psf /= psf.sum(axis=(1, 2), keepdims=True)
    spectrum = flat_spectrum(density=1e-3, aspect=3.0)
    width, height = 6, 2
    nsr = torch.tensor([1e-3, 2e-3, 5e-4], dtype=torch.float64)
    variance = width**2 * 1e-3
    expected = []
    for c in range(3):
        columns = []
        for i in range(height * width):
            impulse = np.zeros((height, width))
            impulse.flat[i] = 1.0
            columns.append(signal.convolve2d(impulse, psf[c], mode="full").ravel())
        h = np.stack(columns, axis=1)
        gram = variance * h.T @ h / float(nsr[c])
        expected.append(0.5 * np.linalg.slogdet(np.eye(h.shape[1]) + gram)[1] / math.log(2))
    got = plate_bits_per_channel(torch.from_numpy(psf), spectrum, width, nsr, method="block")
    np.testing.assert_allclose(got.numpy(), expected, rtol=1e-9)


def test_block_per_pixel_approaches_the_rate_as_plates_grow():
    """Szegő: the border leakage the rate leaves out shrinks relative to the plate as it grows."""
    psf, spectrum = gaussian_psf(1.5), flat_spectrum(1e-4)
    nsr = torch.full((3,), 1e-3, dtype=torch.float64)
    gaps = []
    for width in (8, 16, 32, 64):
        block = plate_bits(psf, spectrum, width, nsr, method="block")
        rate = plate_bits(psf, spectrum, width, nsr, method="rate")
        gaps.append(float(block / rate) - 1)
    assert all(g > 0 for g in gaps), gaps  # the rate alone would not be an upper bound for small plates
    assert gaps == sorted(gaps, reverse=True) and gaps[-1] < 0.15, gaps


@pytest.mark.parametrize("method", ["block", "rate"])
def test_more_noise_never_raises_bits(method):
    psf, spectrum = lens().psf().detach(), smooth_spectrum()
    nsr = torch.full((3,), 1e-4, dtype=torch.float64)
    bits = [float(plate_bits(psf, spectrum, 24, nsr * k, method)) for k in (1, 2, 10, 100, 1e4)]
    assert all(b1 > b2 for b1, b2 in zip(bits, bits[1:])), bits


def test_bits_fall_along_a_defocus_ladder():
    spectrum = smooth_spectrum()
    bits = []
    for focus in (10.0, 7.0, 5.0, 3.5, 2.5):
        cam = lens(focus)
        nsr = noise_to_signal(cam, spectrum.mean_radiance)
        bits.append(float(plate_bits(cam.psf().detach(), spectrum, 24, nsr)))
    assert all(b1 > b2 for b1, b2 in zip(bits, bits[1:])), bits


def test_ideal_lens_at_high_signal_leaks_far_more_than_the_plate_holds():
    spectrum = smooth_spectrum()
    cam = lens(white_level_photons=1e7, full_well_e=1e8, read_noise_e=0.0)
    bits = float(plate_bits(cam.psf().detach(), spectrum, 16, noise_to_signal(cam, spectrum.mean_radiance)))
    assert bits > 20 * ENTROPY
    assert fano_ceiling(bits, ENTROPY) == 1.0


def test_bits_grow_with_frames():
    spectrum, cam = smooth_spectrum(), lens(3.0)
    psf = cam.psf().detach()
    bits = [float(plate_bits(psf, spectrum, 16, noise_to_signal(cam, spectrum.mean_radiance, t))) for t in (1, 2, 10, 30)]
    assert all(b1 < b2 for b1, b2 in zip(bits, bits[1:])), bits


def test_noise_to_signal_is_the_sensor_variance_at_the_operating_level():
    cam = lens()
    nsr = noise_to_signal(cam, (0.5, 0.5, 0.5), frames=4)
    e = 15000.0 * np.array([0.45, 0.60, 0.50])
    np.testing.assert_allclose(nsr.numpy(), (e * 0.5 + 2.0**2) / e**2 / 4, rtol=1e-6)
    with pytest.raises(ValueError, match="frames"):
        noise_to_signal(cam, (0.5, 0.5, 0.5), frames=0)


@pytest.mark.parametrize("method", ["block", "rate"])
def test_gradient_in_zernike_coefficients_matches_finite_differences(method):
    spec = parse_spec({"name": "g", "mask": {"zernike_um": [0.0, 0.1, -0.1, 0.3, 0.2, -0.2],
                                             "bounds_um": [[-0.6, 0.6]] * 6}})
    cam, spectrum = Lens(spec), smooth_spectrum()
    nsr = noise_to_signal(cam, spectrum.mean_radiance)
    assert cam.coefficients_um.requires_grad

    def bits():
        return plate_bits(cam.psf(), spectrum, 12, nsr, method)

    grad = torch.autograd.grad(bits(), cam.coefficients_um)[0].double()
    step, numeric = 1e-2, torch.zeros(6, dtype=torch.float64)
    with torch.no_grad():
        for j in range(6):
            cam.coefficients_um[j] += step
            up = bits()
            cam.coefficients_um[j] -= 2 * step
            down = bits()
            cam.coefficients_um[j] += step
            numeric[j] = (up - down) / (2 * step)
    assert float(grad[1:].abs().max()) > 1e-2  # the test has something to check
    np.testing.assert_allclose(grad[1:].numpy(), numeric[1:].numpy(), rtol=3e-2, atol=1e-2)
    assert abs(float(grad[0])) < 1e-3  # Z1 (piston) does not change the PSF


def test_fano_ceiling_and_certified_width_agree():
    assert fano_ceiling(0.0, 10.0) == pytest.approx(0.1)
    assert fano_ceiling(100.0, 10.0) == 1.0
    spectrum = smooth_spectrum()
    cam = lens(2.5, white_level_photons=30.0)
    psf, nsr = cam.psf().detach(), noise_to_signal(cam, spectrum.mean_radiance)
    width = certified_width(psf, spectrum, nsr, ENTROPY, eps=0.3)
    assert width >= 4
    assert fano_ceiling(float(plate_bits(psf, spectrum, width, nsr, "block")), ENTROPY) <= 0.3
    assert fano_ceiling(float(plate_bits(psf, spectrum, width + 1, nsr, "block")), ENTROPY) > 0.3
    assert certified_width(psf, spectrum, nsr, entropy_bits=ENTROPY, eps=0.5 / ENTROPY) == 0  # eps H < 1


def test_row_and_curve_report_every_width_and_frame_count():
    spectrum, cam = smooth_spectrum(), lens(3.0)
    row = bound_row(cam, spectrum, ENTROPY, widths_px=(8, 16), frames=(1, 5))
    for t in (1, 5):
        assert row[f"bound_bits_w16_t{t}"] > row[f"bound_bits_w8_t{t}"] > 0
        assert 0 < row[f"bound_ceiling_w8_t{t}"] <= 1
        assert isinstance(row[f"bound_width_eps_t{t}"], int)
    assert row["bound_bits_w16_t5"] > row["bound_bits_w16_t1"]
    assert row["bound_width_eps_t5"] <= row["bound_width_eps_t1"]
    assert row["bound_assumptions"] == ASSUMPTIONS
    curve = bound_curve(cam, spectrum, [4, 8, 16], ENTROPY)
    np.testing.assert_allclose(curve["bits"][1:], [row["bound_bits_w8_t1"], row["bound_bits_w16_t1"]], rtol=1e-9)
    assert np.all(np.diff(curve["ceiling"]) >= 0)


def test_noise_is_set_at_the_least_plate_radiance_never_the_mean():
    """Shot noise falls with radiance: the bound's noise must be that of the darkest plate pixel."""
    import dataclasses
    cam = lens(3.0)
    psf = cam.psf().detach()
    measured = dataclasses.replace(smooth_spectrum(), min_radiance=(0.05, 0.05, 0.05))
    row = bound_row(cam, measured, ENTROPY, widths_px=(16,), frames=(1,))
    at_least = float(plate_bits(psf, measured, 16, noise_to_signal(cam, (0.05, 0.05, 0.05))))
    at_mean = float(plate_bits(psf, measured, 16, noise_to_signal(cam, measured.mean_radiance)))
    assert row["bound_bits_w16_t1"] == pytest.approx(at_least, rel=1e-9)
    assert row["bound_noise_radiance_g"] == 0.05
    assert at_least > at_mean
    unmeasured = smooth_spectrum()
    assert unmeasured.noise_radiance() == (0.0, 0.0, 0.0)
    assert bound_curve(cam, unmeasured, [16], ENTROPY)["bits"][0] > at_least


@pytest.mark.skipif(not torch.cuda.is_available(), reason="needs CUDA")
def test_row_of_a_lens_on_cuda_equals_the_cpu_row():
    """The bound's float64 matrices are CPU work whatever device the lens runs on (a `run --device cuda`
    once stopped in the bound task on mixed devices)."""
    spectrum = smooth_spectrum()
    on_cpu = bound_row(lens(3.0), spectrum, ENTROPY, widths_px=(8, 16), frames=(1, 5))
    on_cuda = bound_row(lens(3.0).cuda(), spectrum, ENTROPY, widths_px=(8, 16), frames=(1, 5))
    assert on_cuda.keys() == on_cpu.keys()
    for key, value in on_cpu.items():
        assert on_cuda[key] == (pytest.approx(value, rel=1e-6) if isinstance(value, float) else value), key
