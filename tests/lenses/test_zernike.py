import math

import numpy as np
import pytest

from lenses import zernike_basis
from lenses.zernike import max_gradient, noll_to_nm, pupil_coordinates


def test_noll_indices_follow_noll_1976():
    assert [noll_to_nm(j) for j in range(1, 12)] == [
        (0, 0), (1, 1), (1, -1), (2, 0), (2, -2), (2, 2), (3, -1), (3, 1), (3, -3), (3, 3), (4, 0)]


def test_first_six_terms_match_closed_forms():
    n = 64
    basis = zernike_basis(6, n).double().numpy()
    rho, theta, inside = pupil_coordinates(n)
    expected = [np.ones_like(rho), 2 * rho * np.cos(theta), 2 * rho * np.sin(theta),
                math.sqrt(3) * (2 * rho**2 - 1), math.sqrt(6) * rho**2 * np.sin(2 * theta),
                math.sqrt(6) * rho**2 * np.cos(2 * theta)]
    for j, e in enumerate(expected):
        np.testing.assert_allclose(basis[j][inside], e[inside], atol=1e-6)
        assert np.all(basis[j][~inside] == 0)


def test_orthonormal_over_the_disk():
    basis = zernike_basis(15, 512).double().numpy()
    inside = pupil_coordinates(512)[2]
    flat = basis[:, inside]
    gram = flat @ flat.T / inside.sum()
    np.testing.assert_allclose(gram, np.eye(15), atol=2e-3)


def test_basis_is_cached_but_returned_fresh():
    a = zernike_basis(6, 32)
    a.zero_()
    assert zernike_basis(6, 32).abs().sum() > 0


@pytest.mark.parametrize("j, expected", [(2, 2.0), (4, 4 * math.sqrt(3)), (6, 2 * math.sqrt(6))])
def test_max_gradient_closed_form(j, expected):
    assert max_gradient(j) == pytest.approx(expected, rel=1e-3)


def _noll_table(rho, theta):
    """Noll (1976), Table 1, terms 7..36: (j, closed form)."""
    r, t, s = rho, theta, math.sqrt
    return [
        (7, s(8) * (3 * r**3 - 2 * r) * np.sin(t)), (8, s(8) * (3 * r**3 - 2 * r) * np.cos(t)),
        (9, s(8) * r**3 * np.sin(3 * t)), (10, s(8) * r**3 * np.cos(3 * t)),
        (11, s(5) * (6 * r**4 - 6 * r**2 + 1)),
        (12, s(10) * (4 * r**4 - 3 * r**2) * np.cos(2 * t)), (13, s(10) * (4 * r**4 - 3 * r**2) * np.sin(2 * t)),
        (14, s(10) * r**4 * np.cos(4 * t)), (15, s(10) * r**4 * np.sin(4 * t)),
        (16, s(12) * (10 * r**5 - 12 * r**3 + 3 * r) * np.cos(t)),
        (17, s(12) * (10 * r**5 - 12 * r**3 + 3 * r) * np.sin(t)),
        (18, s(12) * (5 * r**5 - 4 * r**3) * np.cos(3 * t)), (19, s(12) * (5 * r**5 - 4 * r**3) * np.sin(3 * t)),
        (20, s(12) * r**5 * np.cos(5 * t)), (21, s(12) * r**5 * np.sin(5 * t)),
        (22, s(7) * (20 * r**6 - 30 * r**4 + 12 * r**2 - 1)),
        (23, s(14) * (15 * r**6 - 20 * r**4 + 6 * r**2) * np.sin(2 * t)),
        (24, s(14) * (15 * r**6 - 20 * r**4 + 6 * r**2) * np.cos(2 * t)),
        (25, s(14) * (6 * r**6 - 5 * r**4) * np.sin(4 * t)), (26, s(14) * (6 * r**6 - 5 * r**4) * np.cos(4 * t)),
        (27, s(14) * r**6 * np.sin(6 * t)), (28, s(14) * r**6 * np.cos(6 * t)),
        (29, 4 * (35 * r**7 - 60 * r**5 + 30 * r**3 - 4 * r) * np.sin(t)),
        (30, 4 * (35 * r**7 - 60 * r**5 + 30 * r**3 - 4 * r) * np.cos(t)),
        (31, 4 * (21 * r**7 - 30 * r**5 + 10 * r**3) * np.sin(3 * t)),
        (32, 4 * (21 * r**7 - 30 * r**5 + 10 * r**3) * np.cos(3 * t)),
        (33, 4 * (7 * r**7 - 6 * r**5) * np.sin(5 * t)), (34, 4 * (7 * r**7 - 6 * r**5) * np.cos(5 * t)),
        (35, 4 * r**7 * np.sin(7 * t)), (36, 4 * r**7 * np.cos(7 * t)),
    ]


def test_terms_7_to_36_match_nolls_table():
    n = 64
    basis = zernike_basis(36, n).double().numpy()
    rho, theta, inside = pupil_coordinates(n)
    table = _noll_table(rho, theta)
    assert [j for j, _ in table] == list(range(7, 37))
    for j, expected in table:
        np.testing.assert_allclose(basis[j - 1][inside], expected[inside], atol=2e-5, err_msg=f"Z{j}")


def test_noll_indices_7_to_36():
    expected = [(n, m) for n in range(3, 8) for m in range(n % 2, n + 1, 2) for m in ([m] if m == 0 else [m, m])]
    got = [noll_to_nm(j) for j in range(7, 37)]
    assert [(n, abs(m)) for n, m in got] == expected
    assert all((m > 0) == (j % 2 == 0) for j, (_, m) in zip(range(7, 37), got) if m != 0)


def test_36_terms_orthonormal_over_the_disk_by_quadrature():
    """Gauss-Legendre in rho^2 (exact for polynomials of these orders) times a uniform angle grid."""
    from lenses.zernike import zernike_noll
    u, w = np.polynomial.legendre.leggauss(24)
    rho = np.sqrt((u + 1) / 2)  # rho^2 uniform on [0, 1]: the area element rho d rho = d(rho^2) / 2
    theta = np.arange(64) * 2 * np.pi / 64
    rr, tt = np.meshgrid(rho, theta, indexing="ij")
    weight = (w / 2)[:, None] * np.full(64, 1 / 64)[None, :]  # normalised to the disk's area
    terms = np.stack([zernike_noll(j, rr, tt) for j in range(1, 37)])
    gram = np.einsum("iab,jab,ab->ij", terms, terms, weight)
    np.testing.assert_allclose(gram, np.eye(36), atol=1e-12)


@pytest.mark.parametrize("j", [7, 11, 22, 36])
def test_max_gradient_of_higher_orders_is_at_the_rim(j):
    """|grad Z_j| over a fine Cartesian grid of the disk never exceeds max_gradient(j), and reaches it."""
    from lenses.zernike import zernike_noll
    x = np.linspace(-1, 1, 1201)
    xx, yy = np.meshgrid(x, x)
    rho, theta = np.hypot(xx, yy), np.arctan2(yy, xx)
    z = np.where(rho <= 1, zernike_noll(j, np.minimum(rho, 1), theta), np.nan)
    gy, gx = np.gradient(z, x, x)
    assert np.nanmax(np.hypot(gx, gy)) == pytest.approx(max_gradient(j), rel=2e-2)
