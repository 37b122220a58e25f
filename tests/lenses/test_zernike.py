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
