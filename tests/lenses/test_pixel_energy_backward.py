"""The PSF's hand-written backward (lenses.optics.PixelEnergy) against autograd and finite differences."""

import torch

from lenses.optics import Geometry, PupilModel
from lenses.spec import parse_spec

COEFFS = [0.0, 0.1, -0.1, 0.3, 0.2, -0.2]


def small_model(pupil_samples=16, psf_size_px=5):
    return PupilModel(parse_spec({"name": "t", "mask": {"zernike_um": COEFFS}}),
                      Geometry(pupil_samples=pupil_samples, psf_size_px=psf_size_px))


def composite_pixel_energy(model, coefficients_um):
    """The same physics through autograd's own rules, all in double precision: fft2 of the
    zero-padded pupil, |.|^2, G I G^T."""
    size = model.geometry.fft_size
    field = torch.fft.fft2(model.pupil_field(coefficients_um), s=(size, size))
    intensity = field.real**2 + field.imag**2
    integration = model.integration.double()
    return integration @ intensity @ integration.transpose(1, 2)


def test_pixel_energy_and_its_gradient_equal_autograd_through_the_composite():
    model = small_model(pupil_samples=32, psf_size_px=9)
    c = torch.tensor(COEFFS, dtype=torch.float64, requires_grad=True)
    weights = torch.randn(3, 9, 9, dtype=torch.float64, generator=torch.Generator().manual_seed(0))
    ours, ref = model.pixel_energy(c)[0], composite_pixel_energy(model, c)
    # The products with G run in single precision (see PupilModel): agreement to ~1e-7 of the peak.
    torch.testing.assert_close(ours, ref, rtol=0, atol=1e-6 * float(ref.detach().abs().max()))
    (g_ours,) = torch.autograd.grad((ours * weights).sum(), c)
    (g_ref,) = torch.autograd.grad((ref * weights).sum(), c)
    torch.testing.assert_close(g_ours, g_ref, rtol=0, atol=1e-5 * float(g_ref.abs().max()))


def test_first_and_second_derivatives_match_finite_differences():
    model = small_model()
    c = torch.tensor(COEFFS, dtype=torch.float64, requires_grad=True)

    scale = 1 / float(model.pixel_energy(c)[0].detach().max())

    def pixels(coefficients_um):
        return model.pixel_energy(coefficients_um)[0] * scale  # peak 1

    # Steps of 1e-3 um: the pixels are single-precision accurate, so finite differences need steps
    # well above 1e-7 / tolerance; central differences err by ~step^2 relative there.
    assert torch.autograd.gradcheck(pixels, (c,), eps=1e-3, atol=1e-3, rtol=1e-3)
    assert torch.autograd.gradgradcheck(pixels, (c,), eps=1e-3, atol=1e-3, rtol=1e-3)


def test_even_terms_have_exactly_zero_gradient_at_a_flat_mask():
    """At a flat mask the PSF is even in defocus and astigmatism pixel by pixel, so whatever the
    weights, their first derivatives vanish; the double-precision backward keeps them at rounding
    level (far below Adam's epsilon) while the tilt derivatives are of order one."""
    model = small_model(pupil_samples=64, psf_size_px=15)
    c = torch.zeros(6, dtype=torch.float64, requires_grad=True)
    weights = torch.randn(3, 15, 15, dtype=torch.float64, generator=torch.Generator().manual_seed(1))
    psf = model(c)[0]
    (g,) = torch.autograd.grad((psf.double() * weights).sum(), c)
    assert float(g[1:3].abs().min()) > 1e-3
    assert float(g[3:].abs().max()) < 1e-12 * float(g[1:3].abs().max())
