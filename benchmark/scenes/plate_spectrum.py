"""Power spectrum of licence-plate content, estimated from sharp plate crops of the TRAIN scenes.

Estimator. Every plate of the first `n_scenes` training scenes that is fully visible (>= 99 % of its
pixels), not mirrored and at least `min_width_px` wide is cropped from the sharp scene radiance at
its own size w_i x h_i. Per channel the crop's mean is removed, a separable Hann window (without its
zero end-points) applied, and the periodogram |DFT|^2 / sum(window^2) taken: a per-pixel density
S_i(f) whose mean over the DFT grid is the crop's variance. A plate w_i px wide shows at f cycles/px
the content at nu = w_i f cycles per plate width, so each DFT bin of the crop is a sample of
D(nu) = S_i(f) / w_i^2 at nu_x = k_x, nu_y = k_y w_i / h_i. The samples are averaged per bin of a
table over nu_x in -nx..nx and nu_y in (-ny..ny) * aspect; each crop covers the bins below its own
Nyquist frequency, so the high frequencies come from the large plates only. A power law
A_c |nu|^-alpha (one exponent, per-channel amplitude) is fitted by least squares in log-log to the
radial band [nx/4, nx]; it fills the table bins no crop covers and extends D beyond the table.

Least radiance. `min_radiance` is, per channel, the minimum over every pixel of every crop: the
darkest the plate shows (its ink), where the shot noise is least; `lenses.bound` puts the
Gaussian bound's noise there so that the bound stays an upper bound.

Scaling with plate width: a plate w px wide has per-pixel density S_w(f) = w^2 D(w f) (see
`lenses.bound.PlateSpectrum`); its variance is the integral of D over |nu| < w/2, so it is constant
once the band holds the content, and the content moves to lower frequencies as w grows.
"""

from __future__ import annotations

import dataclasses
from pathlib import Path

import numpy as np

from benchmark.store.cache import config_hash, read_verified_json, write_verified_json

from benchmark.scenes import load_scene
from common.plate_render import PLATE_SIZE_M
from benchmark.scenes.records import Scene
from lenses.bound import PlateSpectrum

PLATE_ASPECT = PLATE_SIZE_M[0] / PLATE_SIZE_M[1]


def _window(n: int) -> np.ndarray:
    return np.hanning(n + 2)[1:-1]


def sharp_plate_crops(scenes: list[Scene], min_width_px: int = 16) -> list[np.ndarray]:
    """(h, w, 3) radiance crops of the fully visible, unmirrored plates at least `min_width_px` wide."""
    crops = []
    for scene in scenes:
        for plate in scene.plates:
            x0, y0, x1, y1 = plate.box_xyxy
            if plate.mirrored or plate.visible_fraction < 0.99 or x1 - x0 < min_width_px:
                continue
            crops.append(np.asarray(scene.image[y0:y1, x0:x1], dtype=np.float64))
    return crops


def spectrum_from_crops(crops: list[np.ndarray], nx: int = 64, aspect: float = PLATE_ASPECT) -> PlateSpectrum:
    """The binned density D (see the module docstring) of `crops` and its power-law tail."""
    if not crops:
        raise ValueError("no plate crops to estimate the plate spectrum from; use more training scenes")
    ny = int(np.ceil(nx / aspect))
    sums = np.zeros((3, 2 * ny + 1, 2 * nx + 1))
    counts = np.zeros((2 * ny + 1, 2 * nx + 1))
    for crop in crops:
        h, w = crop.shape[:2]
        window = _window(h)[:, None] * _window(w)[None, :]
        x = (crop - crop.mean(axis=(0, 1))).transpose(2, 0, 1) * window
        density = np.abs(np.fft.fft2(x)) ** 2 / (window**2).sum() / w**2
        kx = np.round(np.fft.fftfreq(w) * w).astype(int)
        ky = np.round(np.fft.fftfreq(h) * w / aspect).astype(int)
        keep_y, keep_x = np.abs(ky) <= ny, np.abs(kx) <= nx
        iy, ix = np.meshgrid(ky[keep_y] + ny, kx[keep_x] + nx, indexing="ij")
        np.add.at(sums, (slice(None), iy, ix), density[:, keep_y][:, :, keep_x])
        np.add.at(counts, (iy, ix), 1)
    covered = counts > 0
    table = np.where(covered, sums / np.maximum(counts, 1), 0.0)
    amplitude, exponent = _fit_tail(table, covered, nx, aspect)
    vy = (np.arange(2 * ny + 1) - ny)[:, None] * aspect
    vx = (np.arange(2 * nx + 1) - nx)[None, :]
    radius = np.maximum(np.hypot(vy, vx), 1.0)
    table = np.where(covered, table, amplitude[:, None, None] * radius ** (-exponent))
    mean = np.mean([c.mean(axis=(0, 1)) for c in crops], axis=0)
    least = np.min([c.min(axis=(0, 1)) for c in crops], axis=0)  # the bound's noise level (lenses.bound)
    return PlateSpectrum(table=table, aspect=aspect, tail_amplitude=tuple(float(a) for a in amplitude),
                         tail_exponent=exponent, mean_radiance=tuple(float(m) for m in mean), n_crops=len(crops),
                         min_radiance=tuple(float(v) for v in least))


def _fit_tail(table: np.ndarray, covered: np.ndarray, nx: int, aspect: float) -> tuple[np.ndarray, float]:
    """Least-squares fit of log D_c = log A_c - alpha log |nu| over covered bins with nx/4 <= |nu| <= nx."""
    ny, half = (table.shape[1] - 1) // 2, (table.shape[2] - 1) // 2
    vy = (np.arange(2 * ny + 1) - ny)[:, None] * aspect
    vx = (np.arange(2 * half + 1) - half)[None, :]
    radius = np.hypot(vy, vx)
    band = covered & (radius >= nx / 4) & (radius <= nx) & (table.min(axis=0) > 0)
    if band.sum() < 8:
        raise ValueError(f"only {int(band.sum())} spectrum bins in the fit band [{nx / 4}, {nx}] cycles per plate"
                         " width; use more or larger training plates")
    log_r = np.log(radius[band])
    log_d = np.log(table[:, band])  # (3, m)
    # Shared slope, one intercept per channel.
    design = np.zeros((3 * log_r.size, 4))
    for c in range(3):
        design[c * log_r.size:(c + 1) * log_r.size, c] = 1.0
        design[c * log_r.size:(c + 1) * log_r.size, 3] = -log_r
    coef, *_ = np.linalg.lstsq(design, log_d.reshape(-1), rcond=None)
    return np.exp(coef[:3]), float(coef[3])


def estimate_plate_spectrum(n_scenes: int = 300, size: tuple[int, int] = (512, 1024), seed: int = 0,
                            min_width_px: int = 16, nx: int = 64) -> PlateSpectrum:
    """Plate spectrum, mean and least radiance from the first `n_scenes` synthetic TRAIN scenes.

    Only the train split is read, so the bound never looks at the scenes it is compared with.
    """
    scenes = (load_scene("synthetic", "train", i, size, seed) for i in range(n_scenes))
    crops = [c for s in scenes for c in sharp_plate_crops([s], min_width_px)]
    return spectrum_from_crops(crops, nx=nx)


def cached_plate_spectrum(cache_dir: Path, n_scenes: int, size: tuple[int, int] = (512, 1024),
                          seed: int = 0) -> PlateSpectrum:
    """`estimate_plate_spectrum`, memoised as JSON in the cache (the estimate reads hundreds of scenes)."""
    # "fields": a new key for the estimate that records min_radiance (older files lack it).
    key = config_hash({"what": "plate-spectrum", "n_scenes": n_scenes, "size": size, "seed": seed,
                       "fields": "min_radiance"})
    path = Path(cache_dir) / "bound" / f"plate-spectrum-{key}.json"
    d = read_verified_json(path)
    if d is not None:
        return PlateSpectrum(table=np.asarray(d["table"]), aspect=d["aspect"],
                             tail_amplitude=tuple(d["tail_amplitude"]), tail_exponent=d["tail_exponent"],
                             mean_radiance=tuple(d["mean_radiance"]), n_crops=d["n_crops"],
                             min_radiance=tuple(d["min_radiance"]))
    spectrum = estimate_plate_spectrum(n_scenes, size, seed)
    d = dataclasses.asdict(spectrum)
    d["table"] = spectrum.table.tolist()
    write_verified_json(path, d)
    return spectrum
