"""The lens family the known-PSF restorer pre-trains on (attacks/training/lens_family.py)."""

from __future__ import annotations

import math

import pytest
import torch

from attacks.training.lens_family import AT_BOUND, DEFOCUS_RANGE_M, MASK_SHARE, LensFamily
from lenses.builtin import SPEC_DIR
from lenses.lens import Lens
from lenses.spec import load_spec


@pytest.fixture(scope="module")
def family() -> LensFamily:
    return LensFamily()


def _draws(family: LensFamily, n: int, seed: int = 0):
    g = torch.Generator().manual_seed(seed)
    return [family.draw(g) for _ in range(n)]


def test_a_draw_is_a_function_of_its_generator(family):
    assert _draws(family, 20, 3) == _draws(family, 20, 3)
    assert _draws(family, 20, 3) != _draws(family, 20, 4)


def test_draws_stay_inside_the_codesign_bounds_and_the_focus_range(family):
    draws = _draws(family, 2000)
    masks = [d for d in draws if d.kind == "mask"]
    for d in masks:
        assert all(lo <= c <= hi for c, (lo, hi) in zip(d.zernike_um, family.bounds_um))
        assert d.focus_distance_m == family.defocus_spec.optics.object_distance_m
    for d in draws:
        if d.kind == "defocus":
            assert DEFOCUS_RANGE_M[0] <= d.focus_distance_m <= DEFOCUS_RANGE_M[1] and not any(d.zernike_um)
    # The shares the module states, within 4.5 binomial standard errors (a false alarm < 1e-5).
    share = len(masks) / len(draws)
    assert abs(share - MASK_SHARE) < 4.5 * math.sqrt(MASK_SHARE * (1 - MASK_SHARE) / len(draws))
    free = [(c, b) for d in masks for c, b in zip(d.zernike_um[1:], family.bounds_um[1:])]
    at_bound = sum(c in b for c, b in free) / len(free)
    assert abs(at_bound - AT_BOUND) < 4.5 * math.sqrt(AT_BOUND * (1 - AT_BOUND) / len(free))


def test_the_in_focus_draw_is_the_ideal_lens_and_nearer_focus_blurs_more(family):
    from attacks.training.lens_family import FamilyLens

    ideal = Lens(load_spec(SPEC_DIR / "ideal.toml"))
    in_focus = family.build(FamilyLens("defocus", (0.0,) * 6, 10.0))

    def spread(lens: Lens) -> float:  # second moment of the green PSF, px^2
        psf = lens.psf()[1].double()
        k = psf.shape[-1]
        y, x = torch.meshgrid(torch.arange(k) - k // 2, torch.arange(k) - k // 2, indexing="ij")
        return float((psf * (x**2 + y**2)).sum())

    size = min(ideal.psf().shape[-1], in_focus.psf().shape[-1])
    def crop(p):
        o = (p.shape[-1] - size) // 2
        return p[:, o:o + size, o:o + size]
    assert torch.allclose(crop(in_focus.psf()), crop(ideal.psf()), atol=1e-5)
    spreads = [spread(family.build(FamilyLens("defocus", (0.0,) * 6, d))) for d in (8.0, 4.0, 2.0)]
    assert spreads == sorted(spreads) and spreads[-1] > 5 * spread(ideal)  # measured 9x at 2 m


def test_a_mask_draw_builds_the_lens_with_its_coefficients(family):
    drawn = next(d for d in _draws(family, 50, 1) if d.kind == "mask")
    lens = family.build(drawn)
    assert lens.coefficients_um.detach().tolist() == pytest.approx(list(drawn.zernike_um), abs=1e-6)
    reference = Lens(load_spec(SPEC_DIR / "codesign.toml"))
    with torch.no_grad():
        reference.coefficients_um.copy_(torch.tensor(drawn.zernike_um))
    assert torch.allclose(lens.psf(), reference.psf())
