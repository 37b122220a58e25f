"""The exported mask: every format read back independently equals the Zernike sum, in the stated units."""

from __future__ import annotations

import csv
import json
from pathlib import Path

import numpy as np
import pytest
from PIL import Image

from lenses.mask_export import FORMATS, height_map, write_height_map, zernike_cartesian
from lenses.spec import parse_spec
from lenses.zernike import zernike_noll

COEFFS_UM = [0.3, -0.31, 0.04, 0.83, -0.39, -1.26]
N = 33


@pytest.fixture(scope="module")
def spec():
    return parse_spec({"name": "test-mask", "mask": {"zernike_um": COEFFS_UM},
                       "optics": {"aperture_diameter_mm": 4.0}})


def reference_um(x_mm: np.ndarray, y_mm: np.ndarray, radius_mm: float = 2.0) -> np.ndarray:
    """The Zernike sum from lenses.zernike's polar terms (the simulation's own basis), in um."""
    rho, theta = np.hypot(x_mm, y_mm) / radius_mm, np.arctan2(y_mm, x_mm)
    return sum(c * zernike_noll(j, rho, theta) for j, c in enumerate(COEFFS_UM, start=1))


def grid_mm() -> tuple[np.ndarray, np.ndarray]:
    """Expected node coordinates: edge to edge of the 4 mm aperture, row 0 at +y, column 0 at -x."""
    c = np.linspace(-2.0, 2.0, N)
    return np.meshgrid(c, c[::-1], indexing="xy")


@pytest.mark.parametrize("j", range(1, 16))
def test_cartesian_terms_equal_the_polar_noll_terms(j):
    u = np.linspace(-1, 1, 41)
    x, y = np.meshgrid(u, u)
    inside = np.hypot(x, y) <= 1
    cart = np.polynomial.polynomial.polyval2d(x, y, zernike_cartesian(j))
    np.testing.assert_allclose(cart[inside], zernike_noll(j, np.hypot(x, y), np.arctan2(y, x))[inside], atol=1e-12)


def test_derivatives_match_finite_differences(spec):
    heights = height_map(spec, N)
    h = 1e-4  # mm
    x, y = grid_mm()
    fd_x = (reference_um(x + h, y) - reference_um(x - h, y)) / (2 * h * 1000)  # um / um
    fd_y = (reference_um(x, y + h) - reference_um(x, y - h)) / (2 * h * 1000)
    fd_xy = (reference_um(x + h, y + h) - reference_um(x + h, y - h) - reference_um(x - h, y + h)
             + reference_um(x - h, y - h)) / (4 * (h * 1000) ** 2)  # 1 / um
    np.testing.assert_allclose(heights.dz_dx, fd_x, atol=1e-9)
    np.testing.assert_allclose(heights.dz_dy, fd_y, atol=1e-9)
    np.testing.assert_allclose(heights.d2z_dxdy_per_um, fd_xy, atol=1e-9)


def test_npy_round_trip(spec, tmp_path):
    path, sidecar = write_height_map(height_map(spec, N), tmp_path / "mask.npy", "npy")
    data = np.load(path, allow_pickle=False)
    x, y = grid_mm()
    inside = np.hypot(x, y) <= 2.0
    assert data.shape == (N, N) and data.dtype == np.float64
    np.testing.assert_allclose(data[inside], reference_um(x, y)[inside], rtol=0, atol=1e-12)
    assert np.isnan(data[~inside]).all()
    meta = json.loads(sidecar.read_text())
    assert meta["height_unit"] == "um" and meta["grid"]["spacing_um"] == pytest.approx(4000.0 / (N - 1))
    assert meta["material"] == "fused-silica" and meta["wavelength_range_nm"] == [460.0, 640.0]
    assert meta["refractive_index"]["550"] == pytest.approx(1.4599, abs=1e-4)


def test_tiff_round_trip_is_32_bit_float_with_metadata(spec, tmp_path):
    path, _ = write_height_map(height_map(spec, N), tmp_path / "mask.tiff", "tiff")
    with Image.open(path) as image:
        assert image.mode == "F"
        data = np.asarray(image)
        meta = json.loads(image.tag_v2[270])
        x_res = float(image.tag_v2[282])
        unit = image.tag_v2[296]
    assert data.dtype == np.float32
    x, y = grid_mm()
    inside = np.hypot(x, y) <= 2.0
    # float32 keeps ~7 significant digits of heights of a few um
    np.testing.assert_allclose(data[inside], reference_um(x, y)[inside], rtol=0, atol=5e-7)
    assert np.isnan(data[~inside]).all()
    assert unit == 3 and 1e4 / x_res == pytest.approx(meta["grid"]["spacing_um"], rel=1e-6)  # pixels per cm
    assert meta["lens"] == "test-mask" and meta["aperture_diameter_mm"] == 4.0


def test_csv_round_trip(spec, tmp_path):
    path, _ = write_height_map(height_map(spec, N), tmp_path / "mask.csv", "csv")
    lines = path.read_text().splitlines()
    header = {line[2:].split(": ", 1)[0]: json.loads(line[2:].split(": ", 1)[1]) for line in lines if line[0] == "#"}
    rows = list(csv.DictReader(line for line in lines if not line.startswith("#")))
    assert header["height_unit"] == "um"
    x = np.array([float(r["x_mm"]) for r in rows])
    y = np.array([float(r["y_mm"]) for r in rows])
    z = np.array([float(r["height_um"]) for r in rows])
    assert len(rows) == int((np.hypot(*grid_mm()) <= 2.0).sum())
    np.testing.assert_allclose(z, reference_um(x, y), rtol=0, atol=1e-12)


def read_gridsag(path: Path) -> tuple[list[str], np.ndarray]:
    lines = path.read_text().splitlines()
    return lines[0].split(), np.array([[float(v) for v in line.split()] for line in lines[1:]])


def test_zemax_gridsag_round_trip(spec, tmp_path):
    path, sidecar = write_height_map(height_map(spec, N), tmp_path / "mask.DAT", "zemax-gridsag")
    head, data = read_gridsag(path)
    nx, ny, delx, dely, unitflag, xdec, ydec = head
    assert (int(nx), int(ny), int(unitflag), float(xdec), float(ydec)) == (N, N, 0, 0.0, 0.0)  # 0: millimetres
    assert float(delx) == float(dely) == pytest.approx(4.0 / (N - 1), rel=1e-15)
    assert data.shape == (N * N, 5)
    # Points run across each row from -x to +x, rows from +y down (the first is the (-x, +y) corner).
    x = -2.0 + float(delx) * (np.arange(N * N) % N)
    y = 2.0 - float(dely) * (np.arange(N * N) // N)
    inside = np.hypot(x, y) <= 2.0 + 1e-12
    np.testing.assert_allclose(data[:, 0] * 1000.0, reference_um(x, y), rtol=0, atol=1e-12)  # sag in mm
    np.testing.assert_array_equal(data[:, 4], np.where(inside, 0, 1))
    h = 1e-4  # slopes are dimensionless: mm of sag per mm
    np.testing.assert_allclose(data[:, 1], (reference_um(x + h, y) - reference_um(x - h, y)) / 2e3 / h, atol=1e-9)
    np.testing.assert_allclose(data[:, 2], (reference_um(x, y + h) - reference_um(x, y - h)) / 2e3 / h, atol=1e-9)
    assert json.loads(sidecar.read_text())["format"] == "zemax-gridsag"


def test_bad_inputs_are_named(spec, tmp_path):
    with pytest.raises(ValueError, match="at least 5 samples"):
        height_map(spec, 4)
    with pytest.raises(ValueError, match="valid: " + ", ".join(FORMATS)):
        write_height_map(height_map(spec, N), tmp_path / "m.x", "stl")
