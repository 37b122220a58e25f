"""mask.max_sag_um: the bounds of a trainable mask as a manufacturing limit on its relief."""

import math

import pytest

from lenses.spec import LensSpecError, load_spec, parse_spec, worst_sag_um

FREE = [0.0, 0.0, 0.0, 0.0, 0.0, 0.0]


def _bounds(j: int, c: float) -> tuple[tuple[float, float], ...]:
    return tuple((-c, c) if i == j else (0.0, 0.0) for i in range(6))


def test_worst_sag_of_single_terms_is_their_closed_form_peak_to_valley():
    # Z2 = 2 rho cos: 4 c; Z4 = sqrt3 (2 rho^2 - 1): 2 sqrt3 c; Z6 = sqrt6 rho^2 cos 2theta: 2 sqrt6 c.
    assert worst_sag_um(_bounds(1, 0.5)) == pytest.approx(2.0, rel=1e-9)
    assert worst_sag_um(_bounds(3, 1.0)) == pytest.approx(2 * math.sqrt(3), rel=1e-9)
    assert worst_sag_um(_bounds(5, 1.0)) == pytest.approx(2 * math.sqrt(6), rel=1e-9)
    assert worst_sag_um(_bounds(0, 0.0)) == 0.0


def test_worst_sag_of_a_box_is_at_least_each_corner_and_at_most_the_sum():
    box = ((0.0, 0.0), (-0.5, 0.5), (-0.5, 0.5), (-1.0, 1.0), (-1.0, 1.0), (-1.0, 1.0))
    singles = [worst_sag_um(tuple(b if i == j else (0.0, 0.0) for i, b in enumerate(box))) for j in range(6)]
    assert max(singles) < worst_sag_um(box) <= sum(singles)


def test_spec_rejects_bounds_beyond_its_max_sag_and_names_the_field():
    raw = {"name": "t", "mask": {"zernike_um": FREE, "bounds_um": [list(b) for b in _bounds(3, 1.0)],
                                 "max_sag_um": 3.0}}
    with pytest.raises(LensSpecError, match=r"peak-to-valley relief of 3\.464 um, more than mask\.max_sag_um = 3\.0"):
        parse_spec(raw)
    raw["mask"]["max_sag_um"] = 3.5
    assert parse_spec(raw).mask.max_sag_um == 3.5
    raw["mask"]["max_sag_um"] = -1
    with pytest.raises(LensSpecError, match="mask.max_sag_um must be > 0"):
        parse_spec(raw)


def test_codesign_start_states_its_manufacturing_limit():
    from lenses.builtin import SPEC_DIR
    spec = load_spec(SPEC_DIR / "codesign.toml")
    assert spec.mask.max_sag_um is not None
    assert worst_sag_um(spec.mask.bounds_um) <= spec.mask.max_sag_um
