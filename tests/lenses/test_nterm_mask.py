"""Zernike masks of any number of Noll terms: the 6-term form unchanged, more terms through the same physics."""

import math

import pytest
import torch

from benchmark.store.cache import config_hash
from lenses import Lens, LensSpecError, load_spec, parse_spec
from lenses.builtin import SPEC_DIR
from lenses.optics import Geometry, PupilModel
from lenses.spec import MAX_ZERNIKE, worst_sag_um

# config_hash(spec.to_dict()) of the shipped specs: published entries, shipped weights and every cache
# entry are keyed by these, so a change to the spec format must leave them as they are (the 16 hex
# digits as integers).
SHIPPED_KEYS = {"codesign": 3433551201055793121, "defocus": 12208156161421386170, "ideal": 14450535302440046818,
                "random-zernike": 2779167093002855583, "sensor-only": 5519142907574203912}
COEFFS_6 = [0.0, 0.1, -0.1, 0.4, 0.2, -0.3]


@pytest.mark.parametrize("name, key", sorted(SHIPPED_KEYS.items()))
def test_shipped_specs_keep_their_cache_keys(name, key):
    assert config_hash(load_spec(SPEC_DIR / f"{name}.toml").to_dict()) == f"{key:016x}"


def test_six_term_dict_is_todays():
    d = parse_spec({"name": "x", "mask": {"zernike_um": COEFFS_6}}).to_dict()
    assert set(d) == {"name", "optics", "mask", "sensor", "simulation", "description"}
    assert d["mask"] == {"zernike_um": tuple(COEFFS_6), "random_amplitude_um": 0.0}


def test_six_terms_padded_with_zeros_give_the_same_psf_exactly():
    six = Lens(parse_spec({"name": "a", "mask": {"zernike_um": COEFFS_6}}))
    fifteen = Lens(parse_spec({"name": "a", "mask": {"zernike_um": COEFFS_6 + [0.0] * 9}}))
    assert six.geometry == fifteen.geometry
    assert torch.equal(six.psf(), fifteen.psf())


def test_a_higher_term_changes_the_psf_as_its_pupil_phase_says():
    """Z11 (primary spherical) alone: the pupil phase is phase_per_um x c x Z11, and the Strehl ratio of a
    small aberration is exp(-sigma^2) (Marechal) with sigma the RMS phase, = phase_per_um x c."""
    c_um = 0.05
    spec = parse_spec({"name": "s", "mask": {"zernike_um": [0.0] * 10 + [c_um]}})
    flat = parse_spec({"name": "f", "mask": {"zernike_um": [0.0] * 11}})
    geometry = Geometry(256, 15)
    model, ideal = PupilModel(spec, geometry), PupilModel(flat, geometry)
    green = 1
    centre = ideal.sampled_intensity(torch.tensor(flat.mask.zernike_um), 1)[green, 7, 7]
    aberrated = model.sampled_intensity(torch.tensor(spec.mask.zernike_um), 1)[green, 7, 7]
    sigma = model.constants.phase_per_um[green] * c_um
    assert float(aberrated / centre) == pytest.approx(math.exp(-sigma**2), abs=2e-3)


def test_gradients_reach_every_term():
    coeffs = [0.0, 0.05, -0.05, 0.2, 0.1, -0.1, 0.05, 0.05, 0.02, -0.02, 0.05, 0.03, -0.03, 0.02, 0.02]
    lens = Lens(parse_spec({"name": "g", "mask": {"zernike_um": coeffs, "bounds_um": [[-0.3, 0.3]] * 15}}))
    weights = torch.randn(lens.psf().shape, generator=torch.Generator().manual_seed(0))
    (grad,) = torch.autograd.grad((lens.psf() * weights).sum(), lens.coefficients_um)
    assert grad.shape == (15,)
    for j in (6, 10, 14):  # finite differences on terms beyond the sixth
        step = torch.zeros(15)
        step[j] = 1e-2
        with torch.no_grad():
            up = (lens.pupil(lens.coefficients_um + step)[0] * weights).sum()
            down = (lens.pupil(lens.coefficients_um - step)[0] * weights).sum()
        assert float(grad[j]) == pytest.approx(float(up - down) / 2e-2, rel=2e-2, abs=1e-4)


def test_worst_sag_by_pairs_agrees_with_corners(monkeypatch):
    import lenses.spec
    box = ((0.0, 0.0), (-0.5, 0.5), (-0.5, 0.5), (-1.0, 1.0), (-1.0, 1.0), (-1.0, 1.0), (-0.2, 0.3))
    corners = worst_sag_um(box)
    monkeypatch.setattr(lenses.spec, "MAX_SAG_CORNERS", 1)
    assert worst_sag_um(box) == pytest.approx(corners, rel=1e-2)


@pytest.mark.slow
def test_fifteen_bounded_terms_check_their_relief():
    bounds = [[0.0, 0.0]] + [[-0.2, 0.2]] * 14
    raw = {"name": "b", "mask": {"zernike_um": [0.0] * 15, "bounds_um": bounds, "max_sag_um": 1.0}}
    with pytest.raises(LensSpecError, match=r"worst mask inside mask.bounds_um has a peak-to-valley relief of"):
        parse_spec(raw)
    raw["mask"]["max_sag_um"] = 20.0
    assert parse_spec(raw).mask.trainable


@pytest.mark.parametrize("mask, pattern", [
    ({"zernike_um": []}, rf"mask\.zernike_um must hold 1 to {MAX_ZERNIKE} Noll coefficients.*got 0"),
    ({"zernike_um": [0.0] * (MAX_ZERNIKE + 1)}, rf"must hold 1 to {MAX_ZERNIKE}.*got {MAX_ZERNIKE + 1}"),
    ({"zernike_um": [0.0] * 15, "bounds_um": [[-1, 1]] * 6}, r"mask\.bounds_um must be a list of 15 \[low, high\]"),
])
def test_bad_term_counts_name_the_field(mask, pattern):
    with pytest.raises(LensSpecError, match=pattern):
        parse_spec({"name": "x", "mask": mask})


def test_aliasing_high_order_term_is_refused_by_name():
    with pytest.raises(LensSpecError, match=r"mask coefficient Z22 \(mask\.zernike_um\[21\] or its bound\)"):
        Lens(parse_spec({"name": "strong", "mask": {"zernike_um": [0.0] * 21 + [60.0]}}))


def test_fifteen_term_example_loads():
    spec = load_spec(SPEC_DIR / "examples" / "zernike-15.toml")
    assert len(spec.mask.zernike_um) == 15
    assert worst_sag_um(tuple((c, c) for c in spec.mask.zernike_um)) <= spec.mask.max_sag_um
