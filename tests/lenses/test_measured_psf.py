"""A measured PSF as the lens: used as given (resampled to the sensor pitch), and bad files refused by field."""

import json
import math
import pickle

import numpy as np
import pytest
import torch

import attacks
import lenses
from lenses import Lens, LensSpecError, load_spec, parse_spec, spec_to_toml
from lenses.builtin import SPEC_DIR
from lenses.measured import overlap_matrix, sensor_psf

EXAMPLE = SPEC_DIR / "examples" / "measured-defocus.toml"


def measured_spec(tmp_path, array, pitch_um=3.45, name="psf.npy", **extra):
    path = tmp_path / name
    np.save(path, array)
    return parse_spec({"name": "m", "measured_psf": {"files": [str(path)], "pixel_pitch_um": pitch_um, **extra}})


def psnr_db(x, y):
    return float(10 * torch.log10(1 / ((x - y) ** 2).mean()))


@pytest.fixture(scope="module")
def defocus():
    return lenses.load("defocus")


def test_defocus_psf_as_measured_gives_the_defocus_lens(tmp_path, defocus):
    """Same PSF, same sensor: the same sensor images for the same noise draws, the same Wiener PSNR."""
    measured = Lens(measured_spec(tmp_path, defocus.psf().detach().numpy()))
    assert measured.spec.kind == "measured-psf" and measured.geometry.psf_size_px == defocus.geometry.psf_size_px
    assert torch.equal(measured.psf(), defocus.psf())
    x = torch.rand(2, 3, 96, 128, generator=torch.Generator().manual_seed(0))
    y_measured = measured(x, generator=torch.Generator().manual_seed(1))
    y_defocus = defocus(x, generator=torch.Generator().manual_seed(1))
    torch.testing.assert_close(y_measured, y_defocus, rtol=0, atol=1e-6)
    scores = []
    for lens, y in ((measured, y_measured), (defocus, y_defocus)):
        wiener = attacks.load("wiener-known-psf")
        wiener.fit(attacks.FitContext(lens=lens))
        scores.append(psnr_db(wiener.restore(y), x))
    assert scores[0] == pytest.approx(scores[1], abs=1e-4)


def test_shipped_example_at_half_pitch_bins_back_to_the_defocus_psf(defocus):
    spec = load_spec(EXAMPLE)
    assert spec.measured_psf is not None and spec.measured_psf.pixel_pitch_um == spec.sensor.pixel_pitch_um / 2
    lens = Lens(spec)
    torch.testing.assert_close(lens.psf(), defocus.psf(), rtol=0, atol=1e-7)
    assert torch.equal(lens.initial_energy_fraction, torch.ones(3))


def _gaussian_pixels(size_px, pitch_um, sigma_um, shift_um=0.0):
    """Closed form: the energy of a unit 2-D Gaussian in each pixel of an odd grid centred on the axis."""
    edges = (np.arange(size_px + 1) - size_px / 2) * pitch_um
    cdf = np.array([0.5 * (1 + math.erf((e - shift_um) / (sigma_um * math.sqrt(2)))) for e in edges])
    line = np.diff(cdf)
    return np.outer(line, line)


def test_resampling_integer_ratio_is_exact_pixel_integration():
    fine = np.stack([_gaussian_pixels(63, 3.45 / 3, s) for s in (3.0, 5.0, 8.0)])  # 63 = 3 x 21
    psf, fraction = sensor_psf(fine, 3.45 / 3, 3.45, 129)
    expected = np.stack([_gaussian_pixels(21, 3.45, s) for s in (3.0, 5.0, 8.0)])
    np.testing.assert_allclose(psf, expected / expected.sum(axis=(1, 2), keepdims=True), atol=1e-12)
    np.testing.assert_allclose(fraction, 1.0)


def test_resampling_any_ratio_keeps_the_energy_and_the_crop_reports_what_it_cut():
    fine = _gaussian_pixels(80, 1.3, 6.0)[None].repeat(3, axis=0)  # an even side, a pitch ratio of 2.65...
    r = overlap_matrix(80, 1.3, 41, 3.45)
    np.testing.assert_allclose(r.sum(axis=0), 1.0, atol=1e-12)  # every measured pixel lands somewhere, once
    _, fraction = sensor_psf(fine, 1.3, 3.45, 129)
    np.testing.assert_allclose(fraction, 1.0)
    wide = _gaussian_pixels(201, 3.45, 60.0)[None].repeat(3, axis=0)
    psf, fraction = sensor_psf(wide, 3.45, 3.45, 15)
    assert psf.shape == (3, 15, 15)
    inside = math.erf(15 * 3.45 / 2 / (60.0 * math.sqrt(2))) ** 2  # the central 15 x 15 px of the Gaussian
    total = math.erf(201 * 3.45 / 2 / (60.0 * math.sqrt(2))) ** 2
    np.testing.assert_allclose(fraction, inside / total, rtol=1e-9)


def test_three_files_one_per_channel(tmp_path, defocus):
    psf = defocus.psf().detach().numpy()
    files = []
    for c, colour in enumerate("rgb"):
        np.save(tmp_path / f"{colour}.npy", psf[c])
        files.append(str(tmp_path / f"{colour}.npy"))
    lens = Lens(parse_spec({"name": "m3", "measured_psf": {"files": files, "pixel_pitch_um": 3.45}}))
    assert torch.equal(lens.psf(), defocus.psf())


def test_a_tiff_image_for_all_channels(tmp_path):
    from PIL import Image
    image = _gaussian_pixels(21, 3.45, 5.0).astype(np.float32)
    Image.fromarray(image, mode="F").save(tmp_path / "psf.tif")
    lens = Lens(parse_spec({"name": "t", "measured_psf": {"files": [str(tmp_path / "psf.tif")],
                                                          "pixel_pitch_um": 3.45}}))
    expected = torch.from_numpy(image / image.sum())
    for c in range(3):
        torch.testing.assert_close(lens.psf()[c], expected, rtol=0, atol=1e-7)


def test_spec_round_trips_and_relative_paths_are_read_from_the_spec_folder(tmp_path, defocus):
    np.save(tmp_path / "psf.npy", defocus.psf().detach().numpy())
    (tmp_path / "cam.toml").write_text('name = "cam"\n[measured_psf]\nfiles = ["psf.npy"]\npixel_pitch_um = 3.45\n')
    spec = load_spec(tmp_path / "cam.toml")
    assert spec.measured_psf is not None and spec.measured_psf.files == (str((tmp_path / "psf.npy").resolve()),)
    as_stored = json.loads(json.dumps(spec.to_dict()))  # as a results file or leaderboard entry holds it
    assert as_stored["measured_psf"]["files"] == ["psf.npy"] and str(tmp_path) not in json.dumps(as_stored)
    assert parse_spec(as_stored, source=spec.source).to_dict() == spec.to_dict()
    back = tmp_path / "back.toml"
    back.write_text(spec_to_toml(spec))
    assert load_spec(back).to_dict() == spec.to_dict()
    assert spec.to_dict()["mask"]["zernike_um"] == ()  # readers of published specs find an empty mask


def _bad(tmp_path, kind):
    good = np.full((3, 9, 9), 1 / 81)
    if kind == "nan":
        return measured_spec_raw(tmp_path, np.where(np.eye(9, dtype=bool), np.nan, good))
    if kind == "negative":
        return measured_spec_raw(tmp_path, good - 0.05)
    if kind == "two-files":
        np.save(tmp_path / "a.npy", good[0])
        return {"files": [str(tmp_path / "a.npy")] * 2, "pixel_pitch_um": 3.45}
    if kind == "four-channels":
        return measured_spec_raw(tmp_path, np.full((4, 9, 9), 0.01))
    if kind == "no-pitch":
        raw = measured_spec_raw(tmp_path, good)
        raw.pop("pixel_pitch_um")
        return raw
    if kind == "not-an-image":
        (tmp_path / "psf.png").write_text("not an image\n")
        return {"files": [str(tmp_path / "psf.png")], "pixel_pitch_um": 3.45}
    if kind == "pickle":
        (tmp_path / "psf.npy").write_bytes(pickle.dumps(good))
        return {"files": [str(tmp_path / "psf.npy")], "pixel_pitch_um": 3.45}
    if kind == "object-array":
        np.save(tmp_path / "psf.npy", np.array([good, "x"], dtype=object), allow_pickle=True)
        return {"files": [str(tmp_path / "psf.npy")], "pixel_pitch_um": 3.45}
    raise AssertionError(kind)


def measured_spec_raw(tmp_path, array):
    np.save(tmp_path / "psf.npy", array)
    return {"files": [str(tmp_path / "psf.npy")], "pixel_pitch_um": 3.45}


BAD = [
    ("nan", r"measured_psf\.files\[0\] \(.*psf\.npy\) has 27 NaN or infinite values; valid: finite values >= 0"),
    ("negative", r"measured_psf\.files\[0\] .* has 243 negative values .*valid: values >= 0"),
    ("two-files", r"measured_psf\.files has 2 files; valid: 1 .* or 3 \(R, G, B\)"),
    ("four-channels", r"measured_psf\.files\[0\] .* 4 channels; valid: a 2-D image or one of 3 channels"),
    ("no-pitch", r"missing field measured_psf\.pixel_pitch_um"),
    ("not-an-image", r"measured_psf\.files\[0\] .*psf\.png\) is not an image Pillow reads"),
    ("pickle", r"measured_psf\.files\[0\] .* is not a numeric \.npy array numpy reads without pickle"),
    ("object-array", r"measured_psf\.files\[0\] .* is not a numeric \.npy array numpy reads without pickle"),
]


@pytest.mark.parametrize("kind, pattern", BAD, ids=[k for k, _ in BAD])
def test_bad_measured_psf_is_one_sentence_naming_the_field(tmp_path, kind, pattern):
    with pytest.raises(LensSpecError, match=pattern) as info:
        parse_spec({"name": "bad", "measured_psf": _bad(tmp_path, kind)})
    assert "\n" not in str(info.value)


@pytest.mark.parametrize("kind", ["nan", "two-files", "no-pitch", "not-an-image"])
def test_bad_measured_psf_run_exits_2_and_caches_nothing(tmp_path, monkeypatch, capsys, kind):
    from benchmark.cli import main
    raw = _bad(tmp_path, kind)
    lines = ['name = "bad"', "[measured_psf]", f"files = {raw['files']!r}".replace("'", '"')]
    lines += [f"pixel_pitch_um = {raw['pixel_pitch_um']}"] if "pixel_pitch_um" in raw else []
    spec = tmp_path / "bad.toml"
    spec.write_text("\n".join(lines) + "\n")
    cache, out = tmp_path / "cache", tmp_path / "out"
    monkeypatch.setenv("PLB_CACHE", str(cache))
    assert main(["run", "--lens", str(spec), "--profile", "smoke", "--out", str(out)]) == 2
    err = capsys.readouterr().err.strip()
    assert err.startswith("error: ") and "measured_psf." in err and len(err.splitlines()) == 1
    assert not cache.exists() or not any(cache.rglob("*"))
    assert not out.exists() or not any(out.rglob("*"))


def test_co_design_is_refused_by_name(tmp_path, defocus):
    np.save(tmp_path / "psf.npy", defocus.psf().detach().numpy())
    raw = {"name": "m", "measured_psf": {"files": [str(tmp_path / "psf.npy")], "pixel_pitch_um": 3.45},
           "mask": {"zernike_um": [0.0] * 6, "bounds_um": [[-1, 1]] * 6}}
    with pytest.raises(LensSpecError, match=r"mask\.bounds_um asks to co-design the lens, but a measured-psf lens"):
        parse_spec(raw)
    from benchmark.codesign.schemes import SCHEMES
    from benchmark.codesign.trainer import CoDesign
    from benchmark.store.profiles import get_profile
    spec = measured_spec(tmp_path, defocus.psf().detach().numpy())
    with pytest.raises(ValueError, match=r"scheme 'gp' trains the optics, but lens spec 'm' is a measured-psf lens"):
        CoDesign(spec, SCHEMES["gp"], get_profile("smoke"), 0, "cpu", tmp_path / "cache")


def test_a_changed_file_is_caught(tmp_path, defocus):
    spec = measured_spec(tmp_path, defocus.psf().detach().numpy())
    with pytest.raises(LensSpecError, match=r"measured_psf\.sha256\[0\] = 'ab' does not match"):
        stored = json.loads(json.dumps(spec.to_dict()))
        parse_spec({**stored, "measured_psf": {**stored["measured_psf"], "sha256": ["ab"]}})
    np.save(tmp_path / "psf.npy", np.ones((3, 5, 5)))
    with pytest.raises(LensSpecError, match=r"measured_psf\.files\[0\] .* changed since the spec was read"):
        Lens(spec)
