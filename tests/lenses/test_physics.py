"""The PSF against closed forms of diffraction theory."""

import math

import numpy as np
import pytest
import scipy.integrate
import scipy.special
import torch

from lenses.optics import Geometry, PupilModel, choose_geometry, mft_kernel, optical_constants
from lenses.spec import parse_spec

GREEN = 1


def spec(zernike=(0.0,) * 6, **optics):
    return parse_spec({"name": "t", "optics": optics, "mask": {"zernike_um": list(zernike)}})


def intensity(s, geometry, coeffs=None, oversample=3):
    model = PupilModel(s, geometry)
    c = torch.tensor(coeffs if coeffs is not None else s.mask.zernike_um, dtype=torch.float64)
    return model.sampled_intensity(c, oversample), model


def test_airy_first_zero_at_1_22_lambda_f_number():
    s = spec()
    c = optical_constants(s)
    # 9 pixels x 61 sub-samples: a 0.057 um grid along the axis through the centre.
    inten, model = intensity(s, Geometry(pupil_samples=512, psf_size_px=9), oversample=61)
    pitch_mm = s.sensor.pixel_pitch_um * 1e-3
    x = (np.arange(9 * 61) - (9 * 61) // 2) * pitch_mm / 61
    for ch in range(3):
        profile = inten[ch, (9 * 61) // 2].numpy()
        expected = 1.22 * c.wavelength_mm[ch] * c.f_number
        window = (x > 0.7 * expected) & (x < 1.3 * expected)
        i = np.flatnonzero(window)[np.argmin(profile[window])]
        # Parabolic refinement of the minimum.
        a, b, cc = profile[i - 1], profile[i], profile[i + 1]
        found = x[i] + 0.5 * (a - cc) / (a - 2 * b + cc) * (x[1] - x[0])
        assert found == pytest.approx(expected, rel=2e-3)
        assert profile[i] < 1e-3 * profile.max()


def airy_intensity(x_mm, y_mm, lambda_f_mm):
    """In-focus Airy pattern with unit total energy, per mm^2: (pi / (4 (lambda F#)^2)) (2 J1(v) / v)^2,
    v = pi r / (lambda F#) (the integral of (2 J1(v)/v)^2 over the plane is 4 (lambda F#)^2 / pi)."""
    v = np.maximum(math.pi * np.hypot(x_mm, y_mm) / lambda_f_mm, 1e-12)
    return (2 * scipy.special.j1(v) / v) ** 2 * math.pi / (4 * lambda_f_mm**2)


def airy_pixel_energy(k, lambda_f_mm, pitch_mm, nodes=24):
    """Energy of the Airy pattern in each of k x k pixels (centre pixel on the axis), (k, k): the
    intensity integrated over each pixel square by nodes x nodes Gauss-Legendre quadrature."""
    t, w = scipy.special.roots_legendre(nodes)
    x = ((np.arange(k) - k // 2)[:, None] + t[None, :] / 2) * pitch_mm  # (k, nodes) per pixel
    wx = np.broadcast_to(w * pitch_mm / 2, x.shape)
    inten = airy_intensity(x.reshape(-1)[None, :], x.reshape(-1)[:, None], lambda_f_mm)  # rows y
    weighted = inten * np.outer(wx.reshape(-1), wx.reshape(-1))
    return weighted.reshape(k, nodes, k, nodes).sum(axis=(1, 3))


def test_airy_reference_quadrature_matches_adaptive_integration():
    """The closed-form reference itself: Gauss-Legendre pixel sums against scipy's adaptive dblquad."""
    lambda_f_mm, pitch_mm = 550e-6 * 5.0, 3.45e-3
    ref = airy_pixel_energy(3, lambda_f_mm, pitch_mm)
    for (row, col) in ((1, 1), (1, 2), (2, 2)):
        y0, x0 = (row - 1 - 0.5) * pitch_mm, (col - 1 - 0.5) * pitch_mm
        exact, _ = scipy.integrate.dblquad(lambda y, x: airy_intensity(x, y, lambda_f_mm),
                                           x0, x0 + pitch_mm, y0, y0 + pitch_mm, epsabs=1e-12)
        assert ref[row, col] == pytest.approx(exact, rel=1e-9)


def test_default_psf_matches_pixel_integrated_airy_within_one_percent():
    """The in-focus ideal lens (F/5, 3.45 um pixels) at the suite's default geometry
    against the closed-form pixel-integrated Airy pattern, every channel, relative L2 < 1 %."""
    s = spec()
    geometry, _ = choose_geometry(s)
    pixels, total = PupilModel(s, geometry).pixel_energy(torch.zeros(6, dtype=torch.float64))
    psf = (pixels.double() / total[:, None, None]).numpy()
    o = s.optics
    # The working F-number from the thin-lens equation, independently of lenses.optics.
    sensor_distance_mm = 1 / (1 / o.focal_length_mm - 1 / (o.focus_distance_m * 1e3))
    f_number = sensor_distance_mm / o.aperture_diameter_mm
    k = geometry.psf_size_px
    k_centre = k // 2
    for ch, wavelength_nm in enumerate(o.wavelengths_nm):
        ref = airy_pixel_energy(k, wavelength_nm * 1e-6 * f_number, s.sensor.pixel_pitch_um * 1e-3)
        rel_l2 = np.linalg.norm(psf[ch] - ref) / np.linalg.norm(ref)
        assert rel_l2 < 0.01, (wavelength_nm, rel_l2)
        assert psf[ch, k_centre, k_centre] == pytest.approx(ref[k_centre, k_centre], rel=0.005)
    # The test tells the models apart: summing 3 x 3 point samples per pixel (the suite's earlier
    # default) puts too much energy in the centre pixel and fails it.
    ss = 3
    midpoint = PupilModel(s, geometry).sampled_intensity(torch.zeros(6, dtype=torch.float64), ss)
    midpoint = (midpoint.reshape(3, k, ss, k, ss).sum(dim=(2, 4)) * (s.sensor.pixel_pitch_um * 1e-3 / ss) ** 2
                / total[:, None, None]).numpy()
    ref_green = airy_pixel_energy(k, o.wavelengths_nm[GREEN] * 1e-6 * f_number, s.sensor.pixel_pitch_um * 1e-3)
    assert np.linalg.norm(midpoint[GREEN] - ref_green) / np.linalg.norm(ref_green) > 0.03


@pytest.mark.parametrize("x_target", [0.5, 1.0, 1.5, 2.5])
def test_defocus_strehl_is_sinc_squared(x_target):
    s0 = spec()
    c = optical_constants(s0)
    lam_um = c.wavelength_mm[GREEN] * 1e3
    c_opd_um = x_target * lam_um / (2 * math.sqrt(3) * math.pi)
    glass_um = c_opd_um / (c.index[GREEN] - 1)
    geometry = Geometry(pupil_samples=512, psf_size_px=3)
    ideal, _ = intensity(s0, geometry)
    aberrated, _ = intensity(s0, geometry, coeffs=[0, 0, 0, glass_um, 0, 0])
    strehl = float(aberrated[GREEN, 4, 4] / ideal[GREEN, 4, 4])  # sub-sample (4, 4) is the optical axis
    assert strehl == pytest.approx((math.sin(x_target) / x_target) ** 2, rel=2e-3, abs=1e-4)


def test_optical_defocus_term_matches_z4_strehl():
    """Defocus via focus distance: psi rho^2 = Z4 term of rms OPD psi lambda / (4 sqrt3 pi) plus piston."""
    s = spec(focus_distance_m=5.0)
    c = optical_constants(s)
    psi = c.defocus_rad[GREEN]
    c_opd = abs(psi) * c.wavelength_mm[GREEN] / (4 * math.sqrt(3) * math.pi)
    x = 2 * math.sqrt(3) * math.pi * c_opd / c.wavelength_mm[GREEN]
    geometry = Geometry(pupil_samples=512, psf_size_px=3)
    ideal, _ = intensity(spec(), geometry)
    blurred, _ = intensity(s, geometry)
    # The on-axis field is the pupil integral whatever z_s is, so the ratio is the Strehl ratio.
    strehl = float(blurred[GREEN, 4, 4] / ideal[GREEN, 4, 4])
    assert strehl == pytest.approx((math.sin(x) / x) ** 2, rel=5e-3)


@pytest.mark.parametrize("term, axis", [(1, 1), (2, 0)])  # Z2 moves along x (columns), Z3 along y (rows)
def test_tilt_moves_centroid_by_4_c_opd_f_number(term, axis):
    s0 = spec()
    c = optical_constants(s0)
    glass_um = 1.5
    coeffs = [0.0] * 6
    coeffs[term] = glass_um
    k = 81
    model = PupilModel(s0, Geometry(pupil_samples=256, psf_size_px=k))
    pixels, _ = model.pixel_energy(torch.tensor(coeffs, dtype=torch.float64))
    pitch_um = s0.sensor.pixel_pitch_um
    pos = (torch.arange(k, dtype=torch.float64) - k // 2) * pitch_um
    for ch in range(3):
        p = pixels[ch] / pixels[ch].sum()
        centroid = float((p.sum(dim=1 - axis) * pos).sum())
        c_opd_um = (c.index[ch] - 1) * glass_um
        assert centroid == pytest.approx(4 * c_opd_um * c.f_number, rel=1e-2)


def test_parseval_energy_fraction_grows_to_one():
    s = spec()
    fractions = []
    for k in (5, 21, 61, 161):
        model = PupilModel(s, Geometry(pupil_samples=256, psf_size_px=k))
        _, frac = model(torch.zeros(6, dtype=torch.float64))
        fractions.append(frac.double())
    for a, b in zip(fractions, fractions[1:]):
        assert bool((b > a).all())
    assert bool((fractions[-1] > 0.995).all()) and bool((fractions[-1] <= 1.0 + 1e-4).all())


def test_mft_matches_zero_padded_fft():
    s = spec(zernike=(0.0, 0.3, -0.2, 0.5, 0.1, -0.4))
    model = PupilModel(s, Geometry(pupil_samples=64, psf_size_px=3))
    u = model.pupil_field(torch.tensor(s.mask.zernike_um, dtype=torch.float64))[GREEN]
    n, pad = 64, 4
    m = n * pad
    big = torch.zeros(m, m, dtype=torch.complex128)
    big[:n, :n] = u
    # FFT frequency k/(m dx); the pupil grid starts at x_0, which adds a linear phase.
    fft = torch.fft.fftshift(torch.fft.fft2(big)) * model.pupil_dx_mm**2
    freqs = (torch.arange(m, dtype=torch.float64) - m // 2) / (m * model.pupil_dx_mm)
    x0 = float(model.pupil_x_mm[0])
    shift = torch.exp(-2j * math.pi * freqs * x0)
    fft = fft * shift[:, None] * shift[None, :]
    lam, zs = model.constants.wavelength_mm[GREEN], model.constants.sensor_distance_mm
    kernel = mft_kernel(freqs * lam * zs, model.pupil_x_mm, lam, zs)
    mft = kernel @ u @ kernel.T * model.pupil_dx_mm**2
    torch.testing.assert_close(mft, fft, atol=1e-9 * float(fft.abs().max()), rtol=0)


def test_too_strong_aberration_names_the_coefficient():
    from lenses import Lens, LensSpecError
    s = parse_spec({"name": "strong", "mask": {"zernike_um": [0, 0, 0, 0, 200.0, 0]}})
    with pytest.raises(LensSpecError, match=r"Z5 \(mask.zernike_um\[4\]"):
        Lens(s)


def test_trainable_lens_sizes_grid_from_bounds():
    from lenses import Lens
    bounds = [[-1.0, 1.0]] * 6
    small = Lens(parse_spec({"name": "a", "mask": {"zernike_um": [0] * 6, "bounds_um": bounds}}))
    start_elsewhere = Lens(parse_spec({"name": "b", "mask": {"zernike_um": [0, 0.5, 0, -0.9, 0, 0],
                                                                "bounds_um": bounds}}))
    assert small.geometry == start_elsewhere.geometry
    # The worst case inside the bounds keeps its energy inside the fixed crop.
    corner = torch.tensor([1.0, 1.0, 1.0, 1.0, 1.0, 1.0])
    _, frac = small.pupil(corner)
    assert bool((frac > 0.97).all())
