"""A phase mask's height map read from a file: the formats ``lenses.mask_export`` writes, read back.

Formats, told apart by the suffix (``SUFFIXES``): ``.npy`` (float heights in um, NaN outside the glass;
read by numpy without pickle), ``.tif``/``.tiff`` (one 32-bit float channel in um; read by Pillow),
``.dat`` (OpticStudio Grid Sag text: a header ``nx ny delx dely unitflag ...``, then ``z dz/dx dz/dy
d2z/dxdy nodata`` per node from the (-x, +y) corner, z in the unitflag's length) and ``.csv``
(``x_mm,y_mm,height_um`` per node inside the aperture, ``#`` comment lines). Arrays are indexed
[row, column] with row 0 at +y and column 0 at -x, as written; the grid's central node lies on the
optical axis. Grid Sag and CSV state their node spacing; npy and TIFF leave it to the spec.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from pathlib import Path

import numpy as np

SUFFIXES = {".npy": "npy", ".tif": "tiff", ".tiff": "tiff", ".dat": "zemax-gridsag", ".csv": "csv"}
ZEMAX_MIN_NODES = 5  # OpticStudio rejects a Grid Sag file with fewer points per side
MAX_READ_SAMPLES = 8193  # per side: what export-mask writes at most
ZEMAX_UNIT_UM = {0: 1e3, 1: 1e4, 2: 25.4e3, 3: 1e6}  # Grid Sag unitflag: mm, cm, in, m


@dataclass(frozen=True)
class ReadHeightMap:
    """A height map read from a file: ``height_um`` (n_y, n_x), row 0 at +y, column 0 at -x, NaN where the
    file holds no glass; ``spacing_um`` the node spacing when the file states it (Zemax, CSV), else None."""

    height_um: np.ndarray
    spacing_um: float | None


def read_height_map(path: Path | str) -> ReadHeightMap:
    """Read a height map in one of FORMATS (told apart by the suffix: SUFFIXES), as ``write_height_map``
    writes it, without executing anything (numpy without pickle, Pillow, plain text).

    Raises ValueError saying what is wrong with the file (unknown suffix, unreadable, wrong shape).
    """
    path = Path(path)
    fmt = SUFFIXES.get(path.suffix.lower())
    if fmt is None:
        raise ValueError(f"has the suffix {path.suffix!r}; valid: {', '.join(SUFFIXES)} (the formats export-mask "
                         "writes)")
    try:
        result = {"npy": _read_npy, "tiff": _read_tiff, "zemax-gridsag": _read_zemax, "csv": _read_csv}[fmt](path)
    except UnicodeDecodeError:
        raise ValueError(f"is not a {fmt} text file (not UTF-8)") from None
    shape = result.height_um.shape
    if len(shape) != 2 or min(shape) < ZEMAX_MIN_NODES or max(shape) > MAX_READ_SAMPLES:
        raise ValueError(f"holds a grid of shape {shape}; valid: 2-D, {ZEMAX_MIN_NODES} to {MAX_READ_SAMPLES} "
                         "nodes a side")
    if bool(np.isinf(result.height_um).any()):
        raise ValueError("holds infinite heights; valid: finite heights in the aperture, NaN outside")
    return result


def _read_npy(path: Path) -> ReadHeightMap:
    try:
        array = np.load(path, allow_pickle=False, mmap_mode="r")  # the shape is checked before reading
    except (ValueError, OSError, EOFError) as exc:
        raise ValueError(f"is not a numeric .npy array numpy reads without pickle ({exc})") from None
    if not isinstance(array, np.ndarray) or array.dtype.kind not in "fiu":
        raise ValueError(f"holds {getattr(array, 'dtype', type(array).__name__)} data; valid: heights in um")
    if array.ndim != 2 or max(array.shape) > MAX_READ_SAMPLES:
        raise ValueError(f"holds an array of shape {array.shape}; valid: a 2-D grid of at most {MAX_READ_SAMPLES} "
                         "a side")
    return ReadHeightMap(np.asarray(array, dtype=np.float64), None)


def _read_tiff(path: Path) -> ReadHeightMap:
    from PIL import Image, UnidentifiedImageError
    try:
        with Image.open(path) as image:
            if max(image.size) > MAX_READ_SAMPLES:
                raise ValueError(f"is {image.size[0]} x {image.size[1]} pixels; valid: at most {MAX_READ_SAMPLES} a side")
            if image.mode not in ("F", "I", "I;16", "I;16B", "I;16L"):
                raise ValueError(f"has Pillow mode {image.mode!r}; valid: one channel of heights in um (32-bit float)")
            image.load()
            array = np.asarray(image.convert("F"), dtype=np.float64)
    except (UnidentifiedImageError, Image.DecompressionBombError, OSError) as exc:
        raise ValueError(f"is not an image Pillow reads ({exc})") from None
    return ReadHeightMap(array, None)


def _numbers(line: str, count: int, what: str) -> list[float]:
    parts = line.replace(",", " ").split()
    if len(parts) < count:
        raise ValueError(f"has a {what} line {line.strip()[:60]!r} with fewer than {count} numbers")
    try:
        return [float(p) for p in parts[:count]]
    except ValueError:
        raise ValueError(f"has a {what} line {line.strip()[:60]!r} that is not numbers") from None


def _read_zemax(path: Path) -> ReadHeightMap:
    lines = [line for line in path.read_text(encoding="utf-8").splitlines() if line.strip() and
             not line.lstrip().startswith("!")]
    if not lines:
        raise ValueError("is empty; valid: a Zemax Grid Sag file (first line: nx ny delx dely unitflag xdec ydec)")
    nx, ny, dx, dy, unit = _numbers(lines[0], 5, "Grid Sag header")
    if nx != int(nx) or ny != int(ny) or not 0 < nx <= MAX_READ_SAMPLES or not 0 < ny <= MAX_READ_SAMPLES:
        raise ValueError(f"states a grid of {nx:g} x {ny:g} nodes; valid: whole numbers up to {MAX_READ_SAMPLES}")
    if int(unit) not in ZEMAX_UNIT_UM or unit != int(unit):
        raise ValueError(f"states unitflag {unit:g}; valid: {sorted(ZEMAX_UNIT_UM)} (mm, cm, in, m)")
    if not (dx > 0 and math.isclose(dx, dy, rel_tol=1e-9)):
        raise ValueError(f"states node spacings delx = {dx:g}, dely = {dy:g}; valid: equal and > 0 (square cells)")
    n_x, n_y, scale = int(nx), int(ny), ZEMAX_UNIT_UM[int(unit)]
    if len(lines) - 1 != n_x * n_y:
        raise ValueError(f"holds {len(lines) - 1} node lines for a {n_x} x {n_y} grid; valid: {n_x * n_y}")
    values = np.array([_numbers(line, 5, "node") for line in lines[1:]])
    height = np.where(values[:, 4] == 0, values[:, 0] * scale, np.nan).reshape(n_y, n_x)
    return ReadHeightMap(height, dx * scale)


def _read_csv(path: Path) -> ReadHeightMap:
    rows = [line for line in path.read_text(encoding="utf-8").splitlines() if line.strip() and not line.startswith("#")]
    if not rows or rows[0].replace(" ", "") != "x_mm,y_mm,height_um":
        raise ValueError("has no header line x_mm,y_mm,height_um; valid: the CSV export-mask writes")
    if len(rows) - 1 > MAX_READ_SAMPLES**2:
        raise ValueError(f"holds {len(rows) - 1} nodes; valid: at most {MAX_READ_SAMPLES}^2")
    points = np.array([_numbers(line, 3, "node") for line in rows[1:]]).reshape(-1, 3)
    xs, ys = np.unique(points[:, 0]), np.unique(points[:, 1])
    if len(xs) < 2 or len(ys) < 2:
        raise ValueError("holds nodes on fewer than two columns or rows; valid: a grid")
    spacing = float(np.diff(xs).min())
    n_x = int(round((xs[-1] - xs[0]) / spacing)) + 1
    n_y = int(round((ys[-1] - ys[0]) / spacing)) + 1
    cols = np.rint((points[:, 0] - xs[0]) / spacing).astype(int)
    rows_ = np.rint((ys[-1] - points[:, 1]) / spacing).astype(int)  # row 0 at +y
    if max(n_x, n_y) > MAX_READ_SAMPLES or not (np.allclose(xs[0] + cols * spacing, points[:, 0], atol=1e-6 * spacing)
                                                and np.allclose(ys[-1] - rows_ * spacing, points[:, 1],
                                                                atol=1e-6 * spacing)):
        raise ValueError("holds nodes that do not lie on one square grid; valid: the CSV export-mask writes")
    height = np.full((n_y, n_x), np.nan)
    height[rows_, cols] = points[:, 2]
    return ReadHeightMap(height, spacing * 1000.0)


def _extend_once(height: np.ndarray) -> np.ndarray:
    """Fill each NaN node next to two valid ones along an axis by linear extrapolation (the mean over the
    axes where it can), so that an interpolation just inside the rim sees a smooth continuation."""
    estimates = []
    padded = np.pad(height, 2, constant_values=np.nan)
    h, w = height.shape
    for dy, dx in ((0, 1), (0, -1), (1, 0), (-1, 0)):
        v1 = padded[2 + dy:2 + dy + h, 2 + dx:2 + dx + w]
        v2 = padded[2 + 2 * dy:2 + 2 * dy + h, 2 + 2 * dx:2 + 2 * dx + w]
        estimates.append(2 * v1 - v2)
    stack = np.stack(estimates)
    count = np.isfinite(stack).sum(axis=0)
    mean = np.where(count > 0, np.nansum(np.where(np.isfinite(stack), stack, 0.0), axis=0) / np.maximum(count, 1),
                    np.nan)
    return np.where(np.isnan(height), mean, height)


def sample_height_map(height_um: np.ndarray, spacing_um: float, pupil_samples: int, radius_um: float) -> np.ndarray:
    """The map (n_y, n_x; NaN outside the glass) at the pupil grid's sample points, (N, N) in um, rows
    along +y, columns along +x (the order of ``lenses.zernike.pupil_coordinates``), zero outside the disk.

    The map's central node lies on the optical axis. NaN nodes are first filled by two rounds of linear
    extrapolation from the valid ones, the rest with the nearest valid value; the pupil samples are then
    bilinear interpolations of the nodes.
    """
    from scipy.interpolate import RegularGridInterpolator
    from scipy.ndimage import distance_transform_edt
    filled = _extend_once(_extend_once(height_um))
    missing = np.isnan(filled)
    if missing.any():
        nearest = distance_transform_edt(missing, return_distances=False, return_indices=True)
        filled = filled[tuple(nearest)]
    n_y, n_x = height_um.shape
    y = (np.arange(n_y) - (n_y - 1) / 2) * spacing_um  # ascending; row 0 of the map is at +y
    x = (np.arange(n_x) - (n_x - 1) / 2) * spacing_um
    interpolate = RegularGridInterpolator((y, x), filled[::-1], method="linear")
    c = ((np.arange(pupil_samples) + 0.5) / pupil_samples * 2 - 1) * radius_um
    yy, xx = np.meshgrid(c, c, indexing="ij")
    inside = np.hypot(xx, yy) <= radius_um
    values = interpolate(np.stack([np.clip(yy, y[0], y[-1]), np.clip(xx, x[0], x[-1])], axis=-1))
    return np.where(inside, values, 0.0)


def max_steps_um(height_um: np.ndarray) -> tuple[float, float]:
    """Largest |difference| (um) between neighbouring valid nodes along x (columns) and along y (rows)."""
    out = []
    for axis in (1, 0):
        steps = np.abs(np.diff(height_um, axis=axis))
        out.append(float(np.nanmax(steps)) if np.isfinite(steps).any() else 0.0)
    return out[0], out[1]
