"""What the marginalising ideal observer is not told about a plate: the nuisance prior, its points,
and the plate's mean raw electrons at each point.

A nuisance point fixes the plate's top-left corner in sensor pixels (both axes), its width in pixels
(the height follows from the plate's aspect) and its exposure; everything else (format, font, colour,
EU band, surround) stays as `PlateModel` tells it. The PSF is shift-invariant, so only the position
modulo the RGGB period (2 px) changes what the sensor records: a corner uniform over [0, 2) px in
each axis is the sub-pixel position and the Bayer parity together.

Rendering. Where the position and width fall on the pixel grid (`pixel-grid` or `known` for both,
one position per pixel, no `area_rendering`) the plate is drawn by the scenes' own `render_plate` at its integer size and pasted at its integer
offset, exactly as the synthetic scenes paste it (so a prior collapsed to the genie's point gives the
genie's means bit for bit). Otherwise the plate is drawn once per text at a fine `master` size
(`render_plate` at >= MASTER_HEIGHT_PX rows) and integrated over each sensor pixel's footprint at the
point's continuous position and scale (`area_weights`: exact box integration of the piecewise-constant
master), the uncovered part of each pixel taking the surround's radiance. That is the physical pixel
integral; Pillow's BOX resize, with which `render_plate` ends, includes or drops whole source pixels by
their centres instead, so the two renderers differ by up to 28 of 255 levels on a 64 x 14 px plate
(`NuisancePrior.area_rendering` puts on-grid points through the integral too).
"""

from __future__ import annotations

import math
import warnings
from dataclasses import dataclass

import numpy as np
import torch
from scipy.stats import qmc

from common.plate_render import render_plate
from lenses.raw_likelihood import raw_mean_electrons

MODES = ("known", "pixel-grid", "continuous")
BAYER_PERIOD_PX = 2
MASTER_HEIGHT_PX = 48


@dataclass(frozen=True)
class NuisancePrior:
    """The prior the observer averages its likelihood over (each point drawn from it, independently of
    the characters).

    position: "continuous": the corner uniform over [0, 2) px in both axes (sub-pixel position and the
    RGGB parity); "pixel-grid": uniform over {0, 1} in both axes (the synthetic scenes paste plates at
    integer pixels); "known": at 0 (the genie's).
    width: "continuous": uniform over the curve's width bin [w, w_high) px, height width / aspect;
    "pixel-grid": the integer widths of [w, w_high), equally likely, height `PlateModel.height_px`;
    "known": w.
    exposure: (low, high), uniform; low == high: known. The synthetic scenes draw 0.85-1.05.
    points: M, the nuisance points the likelihood is averaged over (a scrambled Sobol set: each point
    marginally drawn from the prior; a power of 2 keeps its balance).
    exhaustive: average over every point of the prior instead (`support`; only for a discrete prior:
    position and width not "continuous", exposure known): the exact marginal likelihood, no Monte Carlo.
    position_steps: positions per pixel along each axis of a "pixel-grid" position (1: integer pixels;
    4: a quarter-pixel grid, a discrete stand-in for the continuous position).
    area_rendering: integrate every plate over its pixels' footprints (the module docstring), also where
    it lies on the grid; the scenes' `render_plate` ends with Pillow's BOX resize, which weighs each
    source pixel by whether its centre falls in the output pixel (up to 28 of 255 levels from the exact
    area on a 64 x 14 px plate), so only one renderer compares points on and off the grid fairly.
    """

    position: str = "continuous"
    width: str = "continuous"
    exposure: tuple[float, float] = (0.85, 1.05)
    points: int = 32
    exhaustive: bool = False
    position_steps: int = 1
    area_rendering: bool = False

    def __post_init__(self) -> None:
        for name in ("position", "width"):
            if getattr(self, name) not in MODES:
                raise ValueError(f"NuisancePrior.{name} is {getattr(self, name)!r}; valid: {MODES}")
        low, high = self.exposure
        if not 0 < low <= high:
            raise ValueError(f"NuisancePrior.exposure {self.exposure} must be (low, high) with 0 < low <= high")
        if self.points < 1:
            raise ValueError(f"NuisancePrior.points must be >= 1, got {self.points}")
        if self.position_steps < 1:
            raise ValueError(f"NuisancePrior.position_steps must be >= 1, got {self.position_steps}")
        discrete = self.position != "continuous" and self.width != "continuous" and low == high
        if self.exhaustive and not discrete:
            raise ValueError("NuisancePrior.exhaustive needs a discrete prior: position and width 'pixel-grid' or "
                             f"'known' and a known exposure, got {self}")

    @classmethod
    def known(cls, exposure: float, points: int = 1) -> NuisancePrior:
        """The genie's point: corner at 0, the tabulated width, `exposure` (`points` copies of it)."""
        return cls("known", "known", (exposure, exposure), points)

    @property
    def on_grid(self) -> bool:
        """True when every point lies on the pixel grid (integer corner and width)."""
        return (self.position != "continuous" and self.width != "continuous" and self.position_steps == 1
                and not self.area_rendering)


@dataclass(frozen=True)
class Nuisance:
    """One point: corner (x, y) in px from the canvas's top-left (an R pixel), width and height in px, exposure."""

    x_px: float
    y_px: float
    width_px: float
    height_px: float
    exposure: float


def draw_points(prior: NuisancePrior, width_px: int, width_high_px: float, aspect: float, n: int,
                rng: np.random.Generator, height_of=None) -> list[Nuisance]:
    """`n` nuisance points of plates whose width bin is [width_px, width_high_px), each marginally drawn
    from `prior` (an Owen-scrambled Sobol set seeded from `rng`). height_of(width) -> integer height
    for on-grid widths (`PlateModel.height_px`)."""
    dims = (2 if prior.position != "known" else 0) + (prior.width != "known") + (prior.exposure[0] < prior.exposure[1])
    if dims:
        with warnings.catch_warnings():  # n not a power of 2: still marginally uniform, less balanced
            warnings.simplefilter("ignore", UserWarning)
            u = qmc.Sobol(dims, scramble=True, seed=rng).random(n)
    else:
        u = np.zeros((n, 0))
    col = iter(range(dims))
    if prior.position == "known":
        x = y = np.zeros(n)
    else:
        x, y = (u[:, next(col)] * BAYER_PERIOD_PX for _ in range(2))
        if prior.position == "pixel-grid":
            q = prior.position_steps
            x, y = np.floor(x * q) / q, np.floor(y * q) / q
    if prior.width == "known":
        w = np.full(n, float(width_px))
    else:
        v = u[:, next(col)]
        if prior.width == "continuous":
            w = width_px + v * (width_high_px - width_px)
        else:
            n_int = max(1, math.ceil(width_high_px) - width_px)
            w = width_px + np.floor(v * n_int)
    low, high = prior.exposure
    e = np.full(n, low) if low == high else low + u[:, next(col)] * (high - low)
    integer_width = prior.width != "continuous"
    return [Nuisance(float(x[k]), float(y[k]), float(w[k]),
                     float(height_of(int(w[k])) if integer_width and height_of is not None else w[k] / aspect),
                     float(e[k]))
            for k in range(n)]


def support(prior: NuisancePrior, width_px: int, width_high_px: float, height_of) -> list[Nuisance]:
    """Every point of a discrete prior (`NuisancePrior.exhaustive`), each equally likely: the corners on the
    grid of [0, 2)^2 at 1 / position_steps px (or 0) times the integer widths of [width_px, width_high_px)
    (or width_px)."""
    steps = [k / prior.position_steps for k in range(BAYER_PERIOD_PX * prior.position_steps)]
    corners = [(0, 0)] if prior.position == "known" else [(x, y) for y in steps for x in steps]
    widths = [width_px] if prior.width == "known" else list(range(width_px, max(width_px + 1, math.ceil(width_high_px))))
    return [Nuisance(float(x), float(y), float(w), float(height_of(w)), prior.exposure[0])
            for w in widths for x, y in corners]


def canvas_size(prior: NuisancePrior, width_px: int, width_high_px: float, aspect: float, height_of) -> tuple[int, int]:
    """(rows, columns) of the canvas that holds the plate at every point of `prior` in the bin."""
    span = 0 if prior.position == "known" else BAYER_PERIOD_PX
    if prior.width == "known":
        widest = float(width_px)
    elif prior.width == "pixel-grid":
        widest = float(max(width_px, math.ceil(width_high_px) - 1))
    else:
        widest = float(width_high_px)
    tallest = height_of(int(widest)) if prior.width != "continuous" else widest / aspect
    if prior.on_grid:
        return int(tallest) + (span and 1), int(widest) + (span and 1)
    return math.ceil(tallest + span), math.ceil(widest + span)


def area_weights(n_out: int, n_src: int, start_px: float, length_px: float) -> np.ndarray:
    """(n_out, n_src): the length of output pixel j's span [j, j + 1) covered by source pixel i, when the
    n_src source pixels tile [start_px, start_px + length_px) evenly (exact box integration)."""
    edges = start_px + length_px * np.arange(n_src + 1) / n_src
    lo = np.maximum(np.arange(n_out)[:, None], edges[None, :-1])
    hi = np.minimum(np.arange(1, n_out + 1)[:, None], edges[None, 1:])
    return np.clip(hi - lo, 0.0, None)


def plate_radiance(texts: list[str], points: list[Nuisance], canvas: tuple[int, int], background_rgb, eu_band: bool,
                   surround_radiance: float, on_grid: bool, aspect: float) -> torch.Tensor:
    """Scene radiance (len(texts) * len(points), 3, rows, columns) of each text (outer) at each point
    (inner) on the canvas, the plate's radiance value / 255 * exposure, the rest `surround_radiance`; off the
    grid the plates are integrated from a master of width / height = `aspect`."""
    rows, cols = canvas
    out = np.full((len(texts), len(points), 3, rows, cols), surround_radiance, dtype=np.float64)
    if on_grid:
        cache: dict[tuple[str, int, int], np.ndarray] = {}
        for t, text in enumerate(texts):
            for k, p in enumerate(points):
                w, h = int(p.width_px), int(p.height_px)
                key = (text, w, h)
                if key not in cache:
                    cache[key] = np.asarray(render_plate(text, (w, h), background_rgb, eu_band), dtype=np.float64)
                x, y = int(p.x_px), int(p.y_px)
                out[t, k, :, y:y + h, x:x + w] = cache[key].transpose(2, 0, 1) / 255 * p.exposure
    else:
        tallest = max(p.height_px for p in points)
        master_h = max(MASTER_HEIGHT_PX, math.ceil(tallest))
        masters_by_width: dict[int, np.ndarray] = {}
        for k, p in enumerate(points):
            # A plate of integer size is drawn from the master render_plate itself draws it from (its aspect
            # w / h), so at an integer corner it is render_plate's image to its 8-bit rounding.
            on_pixels = p.width_px == int(p.width_px) and p.height_px == int(p.height_px)
            master_w = round(master_h * (p.width_px / p.height_px if on_pixels else aspect))
            if master_w not in masters_by_width:
                masters_by_width[master_w] = np.stack([
                    np.asarray(render_plate(text, (master_w, master_h), background_rgb, eu_band),
                               dtype=np.float64).transpose(2, 0, 1) / 255 for text in texts])
            masters = masters_by_width[master_w]
            ry = area_weights(rows, master_h, p.y_px, p.height_px)
            rx = area_weights(cols, master_w, p.x_px, p.width_px)
            covered = np.outer(ry.sum(1), rx.sum(1))
            # Each pixel's mean radiance: the plate over the part of it the plate covers, the surround elsewhere.
            out[:, k] = p.exposure * (ry @ masters @ rx.T) + surround_radiance * (1 - covered)
    return torch.from_numpy(out.reshape(len(texts) * len(points), 3, rows, cols))


def nuisance_means(camera, texts: list[str], points: list[Nuisance], canvas: tuple[int, int], model,
                   on_grid: bool) -> torch.Tensor:
    """Mean raw electrons (len(texts), len(points), P) of every text at every nuisance point, over the
    canvas +- the PSF radius (`lenses.raw_likelihood.raw_mean_electrons`, the canvas's top-left an R pixel)."""
    radiance = plate_radiance(texts, points, canvas, model.background_rgb, model.eu_band, model.surround_radiance,
                              on_grid, model.aspect)
    means = raw_mean_electrons(radiance, model.surround_radiance, camera.psf, camera.electrons_per_unit)
    return means.reshape(len(texts), len(points), -1)
