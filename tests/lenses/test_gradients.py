"""Gradients of the sensor image with respect to the mask, first and second order."""

import torch

from lenses import Lens
from lenses.sensor import demosaic_bilinear, mosaic
from lenses.spec import parse_spec


def trainable_lens():
    spec = parse_spec({"name": "g", "mask": {"zernike_um": [0.0, 0.1, -0.1, 0.4, 0.2, -0.3],
                                             "bounds_um": [[-1.0, 1.0]] * 6}})
    return Lens(spec)


def expected_sensor_image(lens, x):
    """The sensor image without the noise draw and the ADC (whose straight-through gradient is by
    definition not the finite difference): irradiance -> QE -> mosaic -> demosaic."""
    return demosaic_bilinear(mosaic(lens.irradiance(x) * lens.gain()[:, None, None]))


def test_finite_difference_gradient_of_sensor_image():
    torch.manual_seed(0)
    lens = trainable_lens()
    x = torch.rand(1, 3, 48, 64, dtype=torch.float64)
    weights = torch.randn(1, 3, 48, 64, dtype=torch.float64)

    def loss():
        return (expected_sensor_image(lens, x).double() * weights).sum()

    grad = torch.autograd.grad(loss(), lens.coefficients_um)[0].double()
    h = 1e-3
    numeric = torch.zeros(6, dtype=torch.float64)
    with torch.no_grad():
        for j in range(6):
            lens.coefficients_um[j] += h
            up = loss()
            lens.coefficients_um[j] -= 2 * h
            down = loss()
            lens.coefficients_um[j] += h
            numeric[j] = (up - down) / (2 * h)
    # Piston (Z1) changes nothing: both gradients ~0 there.
    torch.testing.assert_close(grad, numeric, rtol=2e-2, atol=1e-3 * float(numeric.abs().max()))
    assert float(grad[1:].abs().min()) > 0


def test_second_order_gradient_is_finite_and_nonzero():
    lens = trainable_lens()
    x = torch.rand(2, 3, 40, 40)
    y = lens(x, generator=torch.Generator().manual_seed(0))
    loss = ((y - x * 0.8) ** 2).mean()
    (g,) = torch.autograd.grad(loss, lens.coefficients_um, create_graph=True)
    penalty = (g.norm() - 1) ** 2
    (g2,) = torch.autograd.grad(penalty, lens.coefficients_um)
    assert torch.isfinite(g2).all() and float(g2.abs().sum()) > 0


def test_fixed_lens_has_no_trainable_parameters():
    import lenses
    assert not any(p.requires_grad for p in lenses.load("defocus").parameters())
