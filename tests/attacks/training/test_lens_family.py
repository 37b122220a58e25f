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


def test_near_sharp_draws_keep_the_other_draws_and_stay_near_the_centre(family):
    """A family with near-sharp lenses draws the others exactly as the plain family does (the share is
    decided by a number drawn after theirs); its near-sharp draws keep the tilts whole and the aberrations
    within SHARP_FRACTION of their bounds, at the stated share."""
    from attacks.training.lens_family import SHARP_FRACTION, TILT_TERMS

    with pytest.raises(ValueError, match="sharp_share"):
        LensFamily(1.5)
    sharp_family = LensFamily(0.25)
    plain = _draws(family, 50, 5)
    g = torch.Generator().manual_seed(5)
    assert [sharp_family.draw(g, sharp=False) for _ in range(50)] == plain
    assert "sharp_share" not in family.describe() and sharp_family.describe()["sharp_share"] == 0.25
    forced = [sharp_family.draw(torch.Generator().manual_seed(i), sharp=True) for i in range(300)]
    for d in forced:
        assert d.kind == "mask" and d.focus_distance_m == family.defocus_spec.optics.object_distance_m
        for i, (c, (lo, hi)) in enumerate(zip(d.zernike_um, family.bounds_um)):
            scale = 1.0 if i < TILT_TERMS else SHARP_FRACTION
            assert scale * lo <= c <= scale * hi
    largest = max(abs(c) for d in forced for c in d.zernike_um[TILT_TERMS:])
    assert largest > 0.9 * SHARP_FRACTION * 1.0  # uniform over the whole shrunken box, not a point
    draws = _draws(sharp_family, 2000, 6)
    near = sum(d.kind == "mask" and max(abs(c) for c in d.zernike_um[TILT_TERMS:]) <= SHARP_FRACTION for d in draws)
    # Near-sharp draws, plus the rare plain masks that fall inside the shrunken box (at most 0.4 * 0.2 per
    # term, all three: < 0.1 %), within 4.5 binomial standard errors.
    assert abs(near / len(draws) - 0.25 * 1.0) < 4.5 * math.sqrt(0.25 * 0.75 / len(draws)) + 0.002
