"""Malformed lens specs fail with a message naming the field; specs round-trip through TOML."""

import math

import pytest

import lenses
from lenses import LensSpecError, load_spec, parse_spec, spec_to_toml

GOOD = {"name": "x", "mask": {"zernike_um": [0, 0, 0, 0.2, 0, 0]}}


def with_(section, key, value):
    raw = {"name": "x", "mask": {"zernike_um": [0, 0, 0, 0.2, 0, 0]}}
    raw.setdefault(section, {})[key] = value
    return raw


@pytest.mark.parametrize("raw, pattern", [
    ({"mask": {"zernike_um": [0] * 6}}, "missing field 'name'"),
    ({"name": "x"}, r"missing field mask\.zernike_um"),
    (with_("optics", "focal_length_cm", 2.5), r"unknown key optics\.'focal_length_cm'.*focal_length_mm"),
    (with_("optics", "aperture_diameter_mm", -5.0), r"optics\.aperture_diameter_mm must be > 0"),
    (with_("optics", "aperture_diameter_mm", math.nan), r"optics\.aperture_diameter_mm must be finite"),
    (with_("optics", "focal_length_mm", "25 mm"), r"optics\.focal_length_mm must be a number, got str"),
    (with_("sensor", "quantum_efficiency", [0.4, 0.6]), r"sensor\.quantum_efficiency must have 3 entries"),
    (with_("sensor", "quantum_efficiency", [0.4, 1.6, 0.5]), r"sensor\.quantum_efficiency\[1\]"),
    (with_("sensor", "adc_bits", 10.5), r"sensor\.adc_bits must be an integer"),
    # Values the float32 sensor model cannot represent are refused at load, not left to overflow inside a task.
    (with_("sensor", "adc_bits", 1000), r"sensor\.adc_bits = 1000 .*valid: 1 to 24"),
    (with_("sensor", "white_level_photons", 1e300), r"sensor\.white_level_photons = 1e\+300 .*valid: > 0 to 1e\+15"),
    (with_("sensor", "full_well_e", 1e300), r"sensor\.full_well_e = 1e\+300 .*valid: > 0 to 1e\+15"),
    (with_("sensor", "read_noise_e", 1e20), r"sensor\.read_noise_e = 1e\+20 .*valid: >= 0 to 1e\+15"),
    (with_("optics", "aperture_diameter_mm", 1e9),
     r"sensor\.white_level_photons = 15000.0 times \(optics\.aperture_diameter_mm.*valid: > 0 to 1e\+15"),
    (with_("optics", "wavelengths_nm", [0.64, 0.55, 0.46]), r"wavelengths_nm\[0\].*in nm"),
    (with_("mask", "bounds_um", [[-1, 1]] * 5), r"mask\.bounds_um must be a list of 6"),
    (with_("mask", "bounds_um", [[-0.1, 0.1]] * 6), r"mask\.zernike_um\[3\] = 0.2 lies outside"),
    (with_("simulation", "max_psf_size_px", 34), r"simulation\.max_psf_size_px = 34 must be odd"),
    # Edges a run would exhaust memory on are refused at load, saying what is valid.
    (with_("simulation", "max_psf_size_px", 100001), r"max_psf_size_px = 100001 is too large; valid: 3 to 1025"),
    (with_("simulation", "max_pupil_samples", 100000), r"max_pupil_samples = 100000 is too large; valid: 32 to 8192"),
    ({"name": "x", "mask": {"zernike_um": [0] * 6}, "lens": {}}, r"unknown key 'lens'"),
])
def test_malformed_spec_names_the_field(raw, pattern):
    with pytest.raises(LensSpecError, match=pattern):
        parse_spec(raw)


def test_bad_toml_file_names_the_file(tmp_path):
    bad = tmp_path / "bad.toml"
    bad.write_text("name = 'x'\n[mask\nzernike_um = [0]\n")
    with pytest.raises(LensSpecError, match="bad.toml.*not valid TOML"):
        load_spec(bad)
    with pytest.raises(LensSpecError, match="does not exist"):
        load_spec(tmp_path / "missing.toml")


def test_spec_roundtrips_through_toml(tmp_path):
    spec = lenses.load("random-zernike").spec
    path = tmp_path / "rz.toml"
    path.write_text(spec_to_toml(spec))
    back = load_spec(path)
    assert back.mask.zernike_um == spec.mask.zernike_um
    assert back.optics == spec.optics and back.sensor == spec.sensor and back.simulation == spec.simulation
    lens = lenses.load(str(path))
    assert lens.spec.mask.zernike_um == spec.mask.zernike_um


def test_unknown_lens_name_suggests_close_ones():
    with pytest.raises(lenses.UnknownLensError, match=r"Did you mean 'defocus'"):
        lenses.load("defocs")


def test_builtin_lenses_are_registered_and_honour_the_contract():
    assert {"ideal", "defocus", "random-zernike"} <= set(lenses.available())
    for name in ("ideal", "defocus", "random-zernike"):
        lens = lenses.load(name)
        psf = lens.psf()
        k = psf.shape[-1]
        assert psf.shape == (3, k, k) and k % 2 == 1
        assert float((psf.sum(dim=(1, 2)) - 1).abs().max()) < 1e-5
        assert bool((lens.initial_energy_fraction >= lens.spec.simulation.psf_energy_fraction).all())
    ideal = lenses.load("ideal").psf()
    k = ideal.shape[-1]
    assert all(int(ideal[c].argmax()) == (k // 2) * k + k // 2 for c in range(3))


def test_the_largest_representable_sensor_gives_a_finite_image(tmp_path):
    """The edge of the valid ranges still simulates: the bounds are what the model represents."""
    import torch
    raw = {"name": "edge", "mask": {"zernike_um": [0, 0, 0, 0.2, 0, 0]},
           "sensor": {"adc_bits": 24, "white_level_photons": 1e15, "full_well_e": 1e15, "read_noise_e": 1e15}}
    path = tmp_path / "edge.toml"
    path.write_text(spec_to_toml(parse_spec(raw)))
    image = lenses.load(str(path))(torch.rand(1, 3, 32, 32), generator=torch.Generator().manual_seed(0))
    assert torch.isfinite(image).all() and 0 <= float(image.min()) <= float(image.max()) <= 1
