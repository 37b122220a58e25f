"""A lens's phase mask as a height map a fab can make: glass thickness in micrometres on a stated grid.

The mask thickness is h(x, y) = sum_j c_j Z_j(x / R, y / R) (as in ``lenses.optics``): c_j the spec's Noll
coefficients in um of glass, Z_j RMS-normalised over the unit disk, R half the aperture diameter.
Each Z_j is written here as a polynomial in Cartesian x, y (from (x + iy)^|m| and (x^2 + y^2)^p),
so the height and its derivatives (which Zemax's Grid Sag needs for bicubic interpolation) are
exact, not finite differences.

Grid: n x n nodes spanning the aperture edge to edge, [-R, R] on both axes, spacing 2R / (n - 1),
so the rim lies on the grid and n odd puts a node on the axis. Arrays are indexed [row, column]
with row 0 at +y and column 0 at -x, the order Zemax reads a Grid Sag file in (its first point is
the (-x, +y) corner); x and y are the axes of the Zernike definition (theta from +x towards +y).

Formats (``write_height_map``, read back by ``lenses.height_file.read_height_map``), every one with a
sidecar ``PATH.json`` holding the metadata (which reading ignores: a height-map spec states the grid):
- ``npy``: float64 (n, n) heights in um, NaN outside the clear aperture.
- ``tiff``: 32-bit float (n, n) heights in um, NaN outside the aperture; the metadata as JSON in
  the ImageDescription tag and the grid spacing as the resolution (pixels per cm).
- ``csv``: ``# `` comment lines with the metadata, then ``x_mm,y_mm,height_um`` per node inside
  the aperture.
- ``zemax-gridsag``: OpticStudio's Grid Sag .DAT text: a first line ``nx ny delx dely unitflag xdec
  ydec`` (unitflag 0: lengths in mm), then one line ``z dz/dx dz/dy d2z/dxdy nodata`` per node,
  row by row from the (-x, +y) corner: z in mm, first derivatives dimensionless, the cross
  derivative in 1/mm. Nodes outside the aperture carry nodata = 1 and the polynomial's smooth
  extension (Zemax reads the flag but interpolates through the values; the stop blocks that glass).
"""

from __future__ import annotations

import json
import math
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
from numpy.polynomial import polynomial as P
from scipy.signal import convolve2d

from lenses.height_file import ZEMAX_MIN_NODES
from lenses.materials import refractive_index
from lenses.spec import LensSpec
from lenses.zernike import noll_to_nm

FORMATS = ("npy", "tiff", "zemax-gridsag", "csv")

METADATA_VERSION = 1


def zernike_cartesian(j: int) -> np.ndarray:
    """Coefficients C[a, b] of x^a y^b of the RMS-normalised Noll term Z_j on the unit disk.

    Z_j = N R_n^|m|(rho) trig(m theta) with rho^(n-2k) trig(|m| theta) = (x^2 + y^2)^p times the real
    (cos, m >= 0) or imaginary (sin, m < 0) part of (x + iy)^|m|, p = (n - 2k - |m|) / 2.
    Returns an (n + 1, n + 1) array for ``numpy.polynomial.polynomial.polyval2d(x, y, C)``.
    """
    n, m = noll_to_nm(j)
    am = abs(m)
    angular = np.zeros((am + 1, am + 1))
    for q in range(am + 1):  # binom(|m|, q) x^(|m|-q) (iy)^q; i^q is real for even q, imaginary for odd
        if (q % 2 == 0) == (m >= 0):
            angular[am - q, q] = math.comb(am, q) * (-1) ** (q // 2)
    out = np.zeros((n + 1, n + 1))
    for k in range((n - am) // 2 + 1):
        radial = (-1) ** k * math.factorial(n - k) / (
            math.factorial(k) * math.factorial((n + am) // 2 - k) * math.factorial((n - am) // 2 - k))
        p = (n - 2 * k - am) // 2
        rho2p = np.zeros((2 * p + 1, 2 * p + 1))
        for r in range(p + 1):
            rho2p[2 * r, 2 * (p - r)] = math.comb(p, r)
        term = radial * convolve2d(rho2p, angular)
        out[:term.shape[0], :term.shape[1]] += term
    norm = math.sqrt(n + 1) if m == 0 else math.sqrt(2 * (n + 1))
    return norm * out


@dataclass(frozen=True)
class HeightMap:
    """A mask's thickness on an n x n grid; arrays (n, n), row 0 at +y, column 0 at -x.

    ``height_um`` is the Zernike sum everywhere on the square (its smooth extension past the rim);
    ``inside`` marks the clear aperture (rho <= 1). ``dz_dx`` and ``dz_dy`` are dimensionless
    slopes, ``d2z_dxdy_per_um`` the cross derivative in 1/um. ``x_mm`` (n,) rises, ``y_mm`` (n,) falls.
    """

    height_um: np.ndarray
    dz_dx: np.ndarray
    dz_dy: np.ndarray
    d2z_dxdy_per_um: np.ndarray
    inside: np.ndarray
    x_mm: np.ndarray
    y_mm: np.ndarray
    spacing_um: float
    metadata: dict[str, Any]


def height_map(spec: LensSpec, n_samples: int = 257) -> HeightMap:
    """The mask of ``spec`` on ``n_samples`` x ``n_samples`` nodes spanning its aperture (see module doc).

    Raises ValueError when n_samples < 5 (Zemax's minimum; too few to describe a mask anyway), or when the
    spec's encoder is not a Zernike mask (a height map is its file already; a measured PSF has no mask).
    """
    if spec.kind != "zernike":
        where = f"its mask is the file {spec.height_map.file}" if spec.height_map is not None else "it has no mask"
        raise ValueError(f"lens {spec.name!r} is a {spec.kind} lens: {where}; export-mask writes Zernike masks")
    if isinstance(n_samples, bool) or not isinstance(n_samples, int) or n_samples < ZEMAX_MIN_NODES:
        raise ValueError(f"the mask grid needs at least {ZEMAX_MIN_NODES} samples per side, got {n_samples!r}")
    radius_um = spec.optics.aperture_diameter_mm * 1000.0 / 2.0
    u = np.linspace(-1.0, 1.0, n_samples)  # x / R, columns
    v = u[::-1]  # y / R, rows: row 0 at +y
    uu, vv = np.meshgrid(u, v, indexing="xy")
    coefficients = np.zeros((1, 1))
    for j, c in enumerate(spec.mask.zernike_um, start=1):
        term = c * zernike_cartesian(j)
        size = max(coefficients.shape[0], term.shape[0])
        grown = np.zeros((size, size))
        grown[:coefficients.shape[0], :coefficients.shape[1]] += coefficients
        grown[:term.shape[0], :term.shape[1]] += term
        coefficients = grown
    d_du, d_dv = P.polyder(coefficients, axis=0), P.polyder(coefficients, axis=1)
    height = P.polyval2d(uu, vv, coefficients)
    inside = np.hypot(uu, vv) <= 1.0
    spacing_um = 2.0 * radius_um / (n_samples - 1)
    metadata = _metadata(spec, n_samples, spacing_um, height[inside])
    return HeightMap(
        height_um=height,
        dz_dx=P.polyval2d(uu, vv, d_du) / radius_um,
        dz_dy=P.polyval2d(uu, vv, d_dv) / radius_um,
        d2z_dxdy_per_um=P.polyval2d(uu, vv, P.polyder(d_du, axis=1)) / radius_um ** 2,
        inside=inside,
        x_mm=u * radius_um / 1000.0,
        y_mm=v * radius_um / 1000.0,
        spacing_um=spacing_um,
        metadata=metadata,
    )


def _metadata(spec: LensSpec, n_samples: int, spacing_um: float, inside_heights: np.ndarray) -> dict[str, Any]:
    optics = spec.optics
    wavelengths = [float(w) for w in optics.wavelengths_nm]
    return {
        "metadata_version": METADATA_VERSION,
        "lens": spec.name,
        "quantity": "phase-mask glass thickness h(x, y) = sum_j c_j Z_j(x/R, y/R), Noll order, RMS-normalised",
        "height_unit": "um",
        "zernike_um": [float(c) for c in spec.mask.zernike_um],
        "aperture_diameter_mm": float(optics.aperture_diameter_mm),
        "grid": {"n_x": n_samples, "n_y": n_samples, "spacing_um": spacing_um,
                 "x_range_mm": [-optics.aperture_diameter_mm / 2, optics.aperture_diameter_mm / 2],
                 "y_range_mm": [-optics.aperture_diameter_mm / 2, optics.aperture_diameter_mm / 2],
                 "order": "row 0 at +y, column 0 at -x (Zemax Grid Sag order); nodes on [-R, R] edge to edge"},
        "outside_aperture": "NaN in npy/tiff, left out of csv, nodata = 1 in zemax-gridsag",
        "material": optics.mask_material,
        "wavelengths_nm": wavelengths,
        "wavelength_range_nm": [min(wavelengths), max(wavelengths)],
        "refractive_index": {f"{w:g}": refractive_index(optics.mask_material, w) for w in wavelengths},
        "peak_to_valley_um": float(inside_heights.max() - inside_heights.min()),
        "note": "heights are relative to the substrate plane (piston Z1 included as given); add the substrate's "
                "base thickness, which shifts no PSF",
    }


def write_height_map(heights: HeightMap, path: Path | str, fmt: str) -> list[Path]:
    """Write ``heights`` to ``path`` in ``fmt`` (one of FORMATS) and the metadata to ``path``.json.

    Returns the written paths (data file, metadata file). Raises ValueError on an unknown format.
    """
    if fmt not in FORMATS:
        raise ValueError(f"unknown mask format {fmt!r}; valid: {', '.join(FORMATS)}")
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    {"npy": _write_npy, "tiff": _write_tiff, "zemax-gridsag": _write_zemax, "csv": _write_csv}[fmt](heights, path)
    sidecar = path.with_name(path.name + ".json")
    sidecar.write_text(json.dumps({**heights.metadata, "format": fmt}, indent=1) + "\n")
    return [path, sidecar]


def _masked(heights: HeightMap) -> np.ndarray:
    return np.where(heights.inside, heights.height_um, np.nan)


def _write_npy(heights: HeightMap, path: Path) -> None:
    with path.open("wb") as f:  # np.save(path) would append .npy to a name without it
        np.save(f, _masked(heights))


def _write_tiff(heights: HeightMap, path: Path) -> None:
    from PIL import Image  # 32-bit float ("F") TIFF; Pillow writes its tags without extra packages
    pixels_per_cm = 1e4 / heights.spacing_um
    image = Image.fromarray(_masked(heights).astype(np.float32), mode="F")
    description = json.dumps({**heights.metadata, "format": "tiff"})
    image.save(path, format="TIFF", tiffinfo={270: description, 282: pixels_per_cm, 283: pixels_per_cm, 296: 3})


def _write_csv(heights: HeightMap, path: Path) -> None:
    meta = {**heights.metadata, "format": "csv"}
    lines = [f"# {key}: {json.dumps(value)}" for key, value in meta.items()]
    lines.append("x_mm,y_mm,height_um")
    rows, cols = np.nonzero(heights.inside)
    lines += [f"{float(heights.x_mm[c])!r},{float(heights.y_mm[r])!r},{float(heights.height_um[r, c])!r}"
              for r, c in zip(rows, cols)]
    path.write_text("\n".join(lines) + "\n")


def _write_zemax(heights: HeightMap, path: Path) -> None:
    n_y, n_x = heights.height_um.shape
    spacing_mm = heights.spacing_um / 1000.0
    lines = [f"{n_x} {n_y} {spacing_mm!r} {spacing_mm!r} 0 0 0"]  # unitflag 0: mm; no decentre
    z_mm = heights.height_um / 1000.0
    cross_per_mm = heights.d2z_dxdy_per_um * 1000.0
    for r in range(n_y):
        for c in range(n_x):
            lines.append(f"{z_mm[r, c]:.15e} {heights.dz_dx[r, c]:.15e} {heights.dz_dy[r, c]:.15e} "
                         f"{cross_per_mm[r, c]:.15e} {0 if heights.inside[r, c] else 1}")
    path.write_text("\n".join(lines) + "\n")

