"""A freeform height map as the lens's mask: export-mask's formats read back give the same PSF; bad maps refused."""

import dataclasses
import json
from pathlib import Path

import numpy as np
import pytest
import torch

from lenses import Lens, LensSpecError, load_spec, parse_spec, spec_to_toml
from lenses.builtin import SPEC_DIR
from lenses.height_file import read_height_map
from lenses.mask_export import FORMATS, height_map, write_height_map
from lenses.zernike import zernike_noll

ROOT = Path(__file__).resolve().parents[2]
GP_ENTRY = ROOT / "leaderboard" / "entries" / "gp__quick__synthetic.json"
SUFFIX = {"npy": "npy", "tiff": "tif", "zemax-gridsag": "dat", "csv": "csv"}


@pytest.fixture(scope="module")
def gp():
    """The shipped gp lens's spec, as export-mask reads it from the leaderboard entry."""
    spec = parse_spec(json.loads(GP_ENTRY.read_text())["lens_spec"], source=str(GP_ENTRY))
    fixed = dataclasses.replace(spec.mask, bounds_um=None, max_sag_um=None)  # the same mask, not trained
    return dataclasses.replace(spec, mask=fixed)


def height_spec(path, **grid):
    return parse_spec({"name": "h", "height_map": {"file": str(path), **grid}})


def relative_l2(a, b):
    return (a - b).flatten(1).norm(dim=1) / b.flatten(1).norm(dim=1)


@pytest.mark.parametrize("fmt", FORMATS)
def test_gp_mask_exported_and_read_back_gives_its_psf(tmp_path, gp, fmt):
    path = tmp_path / f"gp.{SUFFIX[fmt]}"
    write_height_map(height_map(gp, 257), path, fmt)
    spec = height_spec(path, **({} if fmt in ("zemax-gridsag", "csv") else {"diameter_mm": 5.0}))
    assert spec.kind == "height-map" and spec.height_map is not None
    assert spec.height_map.sample_pitch_um == pytest.approx(5000.0 / 256, rel=1e-9)
    zernike = Lens(gp)
    read_back = Lens(spec, geometry=zernike.geometry)
    assert float(relative_l2(read_back.psf(), zernike.psf()).max()) < 1e-3
    own = Lens(spec)  # its own grids, chosen from its own PSF as for the Zernike lens
    assert own.geometry == zernike.geometry
    assert float(relative_l2(own.psf(), zernike.psf()).max()) < 1e-3


def test_a_hand_made_map_is_the_zernike_mask_it_samples(tmp_path):
    """An npy written here (not by export-mask): c Z4 + c' Z7 on 201 nodes over a 6 mm square around the 5 mm
    aperture, NaN beyond the 5 mm disk. The lens it makes equals the Zernike lens of those terms."""
    n, half_mm = 201, 3.0
    c = np.linspace(-half_mm, half_mm, n)
    xx, yy = np.meshgrid(c, c[::-1], indexing="xy")
    rho, theta = np.hypot(xx, yy) / 2.5, np.arctan2(yy, xx)
    heights = np.where(rho <= 1, 0.4 * zernike_noll(4, rho, theta) - 0.2 * zernike_noll(7, rho, theta), np.nan)
    np.save(tmp_path / "m.npy", heights)
    spec = height_spec(tmp_path / "m.npy", sample_pitch_um=2 * half_mm * 1000 / (n - 1))
    zernike = Lens(parse_spec({"name": "z", "mask": {"zernike_um": [0, 0, 0, 0.4, 0, 0, -0.2]}}))
    read_back = Lens(spec, geometry=zernike.geometry)
    assert float(relative_l2(read_back.psf(), zernike.psf()).max()) < 1e-3


def test_map_is_fixed_not_trainable():
    lens = Lens(load_spec(SPEC_DIR / "examples" / "gp-height-map.toml"))
    assert not any(p.requires_grad for p in lens.parameters())
    assert lens.psf().grad_fn is None and lens.current_spec().mask.zernike_um == ()


def test_shipped_example_is_the_gp_mask(gp):
    spec = load_spec(SPEC_DIR / "examples" / "gp-height-map.toml")
    zernike = Lens(gp)
    assert float(relative_l2(Lens(spec, geometry=zernike.geometry).psf(), zernike.psf()).max()) < 1e-3


def test_spec_round_trips(tmp_path):
    spec = load_spec(SPEC_DIR / "examples" / "gp-height-map.toml")
    stored = json.loads(json.dumps(spec.to_dict()))
    assert stored["height_map"]["file"] == "gp-mask.npy"  # beside the spec: no path of this machine
    assert parse_spec(stored, source=spec.source).to_dict() == spec.to_dict()
    (tmp_path / "back.toml").write_text(spec_to_toml(spec))  # elsewhere: it names the file absolutely
    back = load_spec(tmp_path / "back.toml")
    assert back.to_dict(absolute_paths=True) == spec.to_dict(absolute_paths=True)
    assert back.to_dict()["height_map"]["file"].endswith("lenses/specs/examples/gp-mask.npy")


def test_a_spec_and_its_file_moved_together_keep_their_dict(tmp_path):
    """The dict is a cache key and what results hold: it does not change with where the folder lies."""
    spec = load_spec(SPEC_DIR / "examples" / "gp-height-map.toml")
    for name in ("gp-height-map.toml", "gp-mask.npy"):
        (tmp_path / name).write_bytes((SPEC_DIR / "examples" / name).read_bytes())
    moved = load_spec(tmp_path / "gp-height-map.toml")
    assert moved.to_dict() == spec.to_dict() and moved.height_map.file != spec.height_map.file
    assert str(tmp_path) not in json.dumps(moved.to_dict())


def test_export_mask_refuses_a_non_zernike_lens():
    spec = load_spec(SPEC_DIR / "examples" / "gp-height-map.toml")
    with pytest.raises(ValueError, match=r"is a height-map lens: its mask is the file .*gp-mask\.npy"):
        height_map(spec)


def _flat(n=65):
    c = np.linspace(-2.5, 2.5, n)
    xx, yy = np.meshgrid(c, c)
    return np.where(np.hypot(xx, yy) <= 2.5, 0.0, np.nan), xx, yy


def _bad(tmp_path, kind):
    heights, xx, yy = _flat()
    grid = {"diameter_mm": 5.0}
    if kind == "aliasing":
        heights = np.where(np.isnan(heights), np.nan, 2.0 * ((np.indices(heights.shape).sum(axis=0)) % 2))
    elif kind == "hole":
        heights[32, 32] = np.nan
    elif kind == "too-small":
        grid = {"diameter_mm": 4.0}
    elif kind == "no-pitch":
        grid = {}
    elif kind == "text-as-npy":
        (tmp_path / "m.npy").write_text("0 0 0\n")
        return {"file": str(tmp_path / "m.npy"), **grid}
    elif kind == "unknown-suffix":
        (tmp_path / "m.txt").write_text("0 0 0\n")
        return {"file": str(tmp_path / "m.txt"), **grid}
    elif kind == "not-an-image":
        (tmp_path / "m.tif").write_text("not a tiff\n")
        return {"file": str(tmp_path / "m.tif"), **grid}
    np.save(tmp_path / "m.npy", heights)
    return {"file": str(tmp_path / "m.npy"), **grid}


BAD = [
    ("aliasing", r"height_map\.file \(.*m\.npy\) has a step of 2 um of glass between neighbouring nodes, .* rad at "
                 r"460 nm: more than pi, so the map aliases; valid: steps up to 0\.4.* um"),
    ("hole", r"height_map\.file .* has 1 NaN nodes inside the clear aperture"),
    ("too-small", r"height_map\.file spans 4 mm .*less than optics\.aperture_diameter_mm = 5\.0"),
    ("no-pitch", r"missing field height_map\.sample_pitch_um .* or height_map\.diameter_mm"),
    ("text-as-npy", r"height_map\.file .* is not a numeric \.npy array numpy reads without pickle"),
    ("unknown-suffix", r"height_map\.file .* has the suffix '\.txt'; valid: \.npy, \.tif"),
    ("not-an-image", r"height_map\.file .* is not an image Pillow reads"),
]


@pytest.mark.parametrize("kind, pattern", BAD, ids=[k for k, _ in BAD])
def test_bad_height_map_is_one_sentence_naming_the_field(tmp_path, kind, pattern):
    with pytest.raises(LensSpecError, match=pattern) as info:
        parse_spec({"name": "bad", "height_map": _bad(tmp_path, kind)})
    assert "\n" not in str(info.value)


def test_aliasing_map_run_exits_2_and_caches_nothing(tmp_path, monkeypatch, capsys):
    from benchmark.cli import main
    raw = _bad(tmp_path, "aliasing")
    spec = tmp_path / "bad.toml"
    spec.write_text(f'name = "bad"\n[height_map]\nfile = "{raw["file"]}"\ndiameter_mm = 5.0\n')
    cache, out = tmp_path / "cache", tmp_path / "out"
    monkeypatch.setenv("PLB_CACHE", str(cache))
    assert main(["run", "--lens", str(spec), "--profile", "smoke", "--out", str(out)]) == 2
    err = capsys.readouterr().err.strip()
    assert err.startswith("error: ") and "height_map.file" in err and "aliases" in err and len(err.splitlines()) == 1
    assert not cache.exists() or not any(cache.rglob("*"))
    assert not out.exists() or not any(out.rglob("*"))


def test_a_steep_map_is_refused_by_the_pupil_grid_guard(tmp_path):
    heights, xx, yy = _flat(257)
    # 100 um of tilt: 0.39 um steps between nodes (no aliasing), ~300 rad of phase slope per unit radius
    np.save(tmp_path / "tilt.npy", np.where(np.isnan(heights), np.nan, 50.0 * xx / 2.5))
    spec = parse_spec({"name": "t", "height_map": {"file": str(tmp_path / "tilt.npy"), "diameter_mm": 5.0},
                       "simulation": {"max_pupil_samples": 128}})
    with pytest.raises(LensSpecError, match=r"the height map \(height_map\.file\) is too strong for the pupil grid"):
        Lens(spec)


def test_grid_stated_twice_must_agree_and_co_design_is_refused(tmp_path, gp):
    path = tmp_path / "gp.dat"
    write_height_map(height_map(gp, 33), path, "zemax-gridsag")
    with pytest.raises(LensSpecError, match=r"the grid stated in the spec \(100 um between nodes\) is not the one "
                                            r"height_map\.file states \(156\.25 um\)"):
        height_spec(path, sample_pitch_um=100.0)
    assert read_height_map(path).spacing_um == pytest.approx(156.25)
    with pytest.raises(LensSpecError, match=r"mask\.bounds_um asks to co-design the lens, but a height-map lens"):
        parse_spec({"name": "h", "height_map": {"file": str(path)}, "mask": {"zernike_um": [0.0] * 6,
                                                                            "bounds_um": [[-1, 1]] * 6}})


def test_a_changed_file_is_caught(tmp_path):
    heights, _, _ = _flat()
    np.save(tmp_path / "m.npy", heights)
    spec = height_spec(tmp_path / "m.npy", diameter_mm=5.0)
    np.save(tmp_path / "m.npy", heights + 0.01)
    with pytest.raises(LensSpecError, match=r"height_map\.file .* changed since the spec was read"):
        Lens(spec)
    assert torch.is_tensor(Lens(height_spec(tmp_path / "m.npy", diameter_mm=5.0)).psf())
