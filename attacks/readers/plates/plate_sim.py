"""Licence plates simulated through a camera, for readers that learn to read what a lens leaves.

An attacker under the lens-access threat model knows the camera (it can measure the PSF with a
point source, the gain with a flat field) and the plate format and font of the country (public).
So it can make as many training plates as it likes: render a random plate string with the
scenes' own renderer (``common.plate_render``), paste it on a cluttered patch, and push the
patch through the camera exactly as a run forms a sensor image (``lens(x, generator)``: the PSF per
colour, gain, shot and read noise, ADC, Bayer mosaic, demosaic).

What varies, so that a reader trained here does not learn one rendering: the plate's width
(log-uniform over the range asked, height from the EU aspect 0.11/0.52 m), its string, its
background (white 80 %, yellow 20 %, like the scenes), the EU band (50 %), a per-channel tint and
haze, the exposure, the patch's colour and clutter (bars and blobs of other colours next to the
plate), the integer position (both Bayer phases) and the box a detector would give (jitter).

``plate_crops`` turns a box on an image into the reader's fixed-size input (the same function at
training and at reading, so the two cannot drift apart): the box grown by a margin that holds the
PSF's spread, resampled by RoIAlign with area averaging, each channel standardised.
"""

from __future__ import annotations

import dataclasses
import math
from collections.abc import Callable, Sequence

import numpy as np
import torch
from torch import Tensor
from torchvision.ops import roi_align

from common.plate_render import PLATE_SIZE_M, format_alphabets, random_plate_text, render_plate

__all__ = ["CROP_HW", "PlateBatch", "crop_margin_px", "plate_crops", "psf_radius_px", "psf_support_px", "simulate_plates"]

CROP_HW: tuple[int, int] = (24, 96)
"""The reader's input (height, width) in pixels: 96 columns give a 7-character plate 13 px per glyph."""

_ASPECT = PLATE_SIZE_M[1] / PLATE_SIZE_M[0]
_WHITE, _YELLOW = (236, 236, 228), (240, 210, 40)
_HAZE = np.array([0.62, 0.66, 0.72], dtype=np.float32)


@dataclasses.dataclass
class PlateBatch:
    """Simulated plates: the reader's input crops (N, 3, *CROP_HW), the per-slot class indices
    (N, slots) into each slot's alphabet, the strings, the plate widths in pixels, and the images
    (N, 3, H, W) with each plate's box on them (the box the crop was cut from; None where a caller
    keeps only the crops)."""

    crops: Tensor
    labels: Tensor
    texts: list[str]
    widths_px: list[int]
    images: Tensor | None
    boxes: list[tuple[float, float, float, float]]


def psf_radius_px(psf: Tensor, energy: float = 0.8) -> float:
    """Radius (pixels) around the PSF's centroid holding ``energy`` of its light, averaged over the
    colours: how far a plate's light spreads on the sensor. ``psf`` (3, K, K), channels summing to 1."""
    k = psf.shape[-1]
    y, x = torch.meshgrid(torch.arange(k, dtype=torch.float64), torch.arange(k, dtype=torch.float64), indexing="ij")
    radii = []
    for channel in psf.detach().to(torch.float64):
        w = channel / channel.sum()
        cy, cx = float((w * y).sum()), float((w * x).sum())
        r = torch.sqrt((y - cy) ** 2 + (x - cx) ** 2).flatten()
        order = torch.argsort(r)
        cumulative = torch.cumsum(w.flatten()[order], 0)
        radii.append(float(r[order][int(torch.searchsorted(cumulative, torch.tensor(energy, dtype=torch.float64)))]))
    return float(np.mean(radii))


def psf_support_px(psf: Tensor, energy: float = 0.995) -> int:
    """Radius (whole pixels) around the PSF array's centre, the point a scene point maps to, inside which
    every colour holds at least ``energy`` of its light; at most half the support. How far beyond a crop
    the light that reaches it comes from: a plate patch simulated with this margin (``simulate_plates``'
    ``psf_half_px``) misses at most ``1 - energy`` of the surround's light at the crop, where the full
    support of a co-designed PSF (87 px) makes the patch, and its transform, up to a third larger.
    ``psf`` (3, K, K), each channel summing to 1, K odd."""
    k = psf.shape[-1]
    c = k // 2
    y, x = torch.meshgrid(torch.arange(k, dtype=torch.float64), torch.arange(k, dtype=torch.float64), indexing="ij")
    r = torch.maximum((y - c).abs(), (x - c).abs()).flatten()  # the square rings a square patch margin adds
    order = torch.argsort(r, stable=True)
    rings = r[order]
    radius = 0
    for channel in psf.detach().to(torch.float64):
        cumulative = torch.cumsum((channel / channel.sum()).flatten()[order], 0)
        inside = int(torch.searchsorted(cumulative, torch.tensor(energy - 1e-12, dtype=torch.float64)))
        radius = max(radius, int(rings[min(inside, rings.numel() - 1)]))
    return min(radius, c)


def crop_margin_px(box_wh: tuple[float, float], spread_px: float) -> tuple[float, float]:
    """(x, y) margin added on each side of a plate box before cropping: a little surround (15 % of
    the width, 30 % of the height) plus the PSF's spread, where the plate's light went."""
    w, h = box_wh
    return 0.15 * w + spread_px, 0.3 * h + spread_px


def plate_crops(images: Tensor, boxes: Sequence[tuple[int, tuple[float, float, float, float]]], spread_px: float
                ) -> Tensor:
    """The reader's inputs (N, 3, *CROP_HW) for ``boxes`` = [(image index, (x0, y0, x1, y1))] on
    ``images`` (B, 3, H, W): each box grown by ``crop_margin_px``, resampled with RoIAlign (bilinear
    samples averaged over each output cell, so a large box is area-averaged, not aliased), then
    each channel standardised over the crop (the tint, exposure and gain carry no text)."""
    if not boxes:
        return images.new_zeros((0, 3, *CROP_HW))
    rois = []
    for index, (x0, y0, x1, y1) in boxes:
        mx, my = crop_margin_px((x1 - x0, y1 - y0), spread_px)
        rois.append([float(index), x0 - mx, y0 - my, x1 + mx, y1 + my])
    crops = roi_align(images.float(), torch.tensor(rois, dtype=torch.float32, device=images.device), CROP_HW,
                      spatial_scale=1.0, sampling_ratio=-1, aligned=True)
    mean = crops.mean(dim=(2, 3), keepdim=True)
    std = crops.std(dim=(2, 3), keepdim=True)
    return (crops - mean) / (std + 1e-3)


def _log_uniform(rng: np.random.Generator, low: float, high: float) -> float:
    return float(math.exp(rng.uniform(math.log(low), math.log(high))))


def _patch(rng: np.random.Generator, hw: tuple[int, int]) -> np.ndarray:
    """A cluttered background (H, W, 3) float32 in [0, 1]: a body colour with a smooth shading
    gradient, a few bars and blobs of other colours (bumpers, lights, shadows) and fine texture."""
    h, w = hw
    base = rng.uniform(0.05, 0.9, size=3).astype(np.float32)
    # The shading as a column plus a row, broadcast: the values of the full (H, W) grids, at a fraction of the work.
    yy, xx = np.arange(h, dtype=np.float32)[:, None], np.arange(w, dtype=np.float32)[None, :]
    gradient = 1.0 + rng.uniform(-0.25, 0.25) * (yy / max(h, 1) - 0.5) + rng.uniform(-0.15, 0.15) * (xx / max(w, 1) - 0.5)
    patch = base[None, None, :] * gradient[..., None]
    for _ in range(int(rng.integers(0, 5))):
        y0, x0 = int(rng.integers(0, h)), int(rng.integers(0, w))
        bh, bw = int(rng.integers(1, max(2, h // 2))), int(rng.integers(1, max(2, w // 2)))
        patch[y0:y0 + bh, x0:x0 + bw] = rng.uniform(0.0, 1.0, size=3)
    patch *= 1.0 + 0.03 * rng.standard_normal((h, w, 1)).astype(np.float32)
    return np.clip(patch, 0.0, 1.0)


def _plate_image(rng: np.random.Generator, text: str, size: tuple[int, int]) -> np.ndarray:
    """The rendered plate (h, w, 3) float32 in [0, 1] with a random background, band, tint and haze."""
    background = _WHITE if rng.random() < 0.8 else _YELLOW
    plate = np.asarray(render_plate(text, size, background, eu_band=bool(rng.random() < 0.5)), dtype=np.float32) / 255
    tint = rng.uniform(0.75, 1.0, size=3).astype(np.float32)
    haze = rng.uniform(0.0, 0.3)
    return (1 - haze) * plate * tint + haze * _HAZE * tint


def simulate_plates(camera: Callable[[Tensor, torch.Generator], Tensor] | None, n: int, widths_px: tuple[float, float],
                    rng: np.random.Generator, generator: torch.Generator, spread_px: float, fmt: str,
                    psf_half_px: int = 0, jitter: bool = True) -> PlateBatch:
    """``n`` plates of one width band through ``camera``, as the reader's input crops.

    Args:
        camera: ``lens(x, generator)`` (B, 3, H, W) radiance in [0, 1] -> sensor image; None: the
            rendered scene itself (clean plates, no lens and no noise).
        n: Plates in the batch.
        widths_px: The band (low, high) the batch's base width is drawn from, log-uniform; each plate
            then varies by +-5 % around it (a batch shares one patch size, so one camera call).
        rng, generator: The scene draws and the camera's noise; the same pair gives the same batch.
        spread_px: The PSF's spread (``psf_radius_px``) the crop margin holds.
        fmt: Plate format (e.g. 'LLDDDLL').
        psf_half_px: How far the PSF spreads light (half its support, or ``psf_support_px``): the patch
            extends this far beyond every crop, so the light that reaches the crop from outside it is simulated.
        jitter: Move and scale the box as a detector's would (training); False: the true box.
    """
    alphabets = format_alphabets(fmt)
    base = _log_uniform(rng, *widths_px)
    widths = [max(4, round(base * rng.uniform(0.95, 1.05))) for _ in range(n)]
    heights = [max(2, round(w * _ASPECT)) for w in widths]
    mx, my = crop_margin_px((max(widths), max(heights)), spread_px)
    # Room for the jittered crop (its margin, grown 20 %) and for the light that reaches it from outside.
    pad_x, pad_y = (int(math.ceil(m * 1.2)) + psf_half_px + 4 for m in (mx, my))
    shift = 3
    hw = (max(heights) + 2 * pad_y + shift, max(widths) + 2 * pad_x + shift)
    scenes = np.empty((n, *hw, 3), dtype=np.float32)
    texts, boxes = [], []
    for i, (w, h) in enumerate(zip(widths, heights)):
        text = random_plate_text(rng, fmt)
        patch = _patch(rng, hw)
        x0, y0 = pad_x + int(rng.integers(0, shift + 1)), pad_y + int(rng.integers(0, shift + 1))
        patch[y0:y0 + h, x0:x0 + w] = _plate_image(rng, text, (w, h))
        scenes[i] = patch * rng.uniform(0.85, 1.05)
        box = (float(x0), float(y0), float(x0 + w), float(y0 + h))
        if jitter:
            s = rng.uniform(0.93, 1.07)
            cx, cy = (box[0] + box[2]) / 2 + rng.normal(0, 0.04 * w), (box[1] + box[3]) / 2 + rng.normal(0, 0.1 * h)
            hw_, hh_ = w * s / 2, h * rng.uniform(0.9, 1.1) * s / 2
            box = (cx - hw_, cy - hh_, cx + hw_, cy + hh_)
        texts.append(text)
        boxes.append((i, box))
    x = torch.from_numpy(np.clip(scenes, 0.0, 1.0)).permute(0, 3, 1, 2).contiguous()
    with torch.no_grad():
        sensor = x if camera is None else camera(x, generator)
    labels = torch.tensor([[alphabet.index(c) for c, alphabet in zip(t, alphabets)] for t in texts], dtype=torch.long)
    return PlateBatch(plate_crops(sensor, boxes, spread_px), labels, texts, widths, sensor, [b for _, b in boxes])
