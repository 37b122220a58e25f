"""Scenes to tensors, tensors through a lens to sensor images, and attackers' training pairs."""

from __future__ import annotations

from collections.abc import Callable, Iterator

import numpy as np
import torch

import lenses
from common.crops import random_crops
from benchmark.runner.config import RunConfig
from benchmark.scenes import Scene, load_scenes
from benchmark.scenes.windows import PlateWindow


def to_tensor(scenes: list[Scene]) -> torch.Tensor:
    """Scene images -> (N,3,H,W) float32 in [0,1]."""
    return torch.from_numpy(np.stack([s.image for s in scenes])).permute(0, 3, 1, 2).contiguous()


def batches(x: torch.Tensor, size: int) -> Iterator[torch.Tensor]:
    """Consecutive slices of `x` along the batch axis, `size` items each (the last may be shorter)."""
    for i in range(0, x.shape[0], size):
        yield x[i:i + size]


def sense(lens: lenses.Lens, sharp: torch.Tensor, batch_size: int, seed: int, device: str) -> torch.Tensor:
    """Sensor images (N,3,H,W) in [0,1] of `sharp` through `lens`, noise drawn from a generator
    seeded with `seed`; computed on `device`, returned on the CPU."""
    gen = torch.Generator(device=device).manual_seed(seed)
    with torch.no_grad():
        return torch.cat([lens(b.to(device), generator=gen).cpu() for b in batches(sharp, batch_size)])


# splitmix64's finaliser constants (Steele, Lea & Flood 2014): a bijective 64-bit mixer.
_MIX = (np.uint64(0xBF58476D1CE4E5B9), np.uint64(0x94D049BB133111EB))
_GOLDEN = np.uint64(0x9E3779B97F4A7C15)


def _mix64(z: np.ndarray) -> np.ndarray:
    z = (z ^ (z >> np.uint64(30))) * _MIX[0]
    z = (z ^ (z >> np.uint64(27))) * _MIX[1]
    return z ^ (z >> np.uint64(31))


def noise_key(seed: int, scene: Scene) -> int:
    """The 64-bit key of a frame's sensor noise under run seed `seed` (distinct per scene and seed)."""
    return int(np.random.SeedSequence([seed, scene.seed]).generate_state(1, np.uint64)[0])


def positional_normal(key: int, rows: range, cols: range) -> torch.Tensor:
    """Standard normal draws (len(rows), len(cols)) float32, each a function of (key, row, col) only.

    A counter-based generator: pixel (y, x) of a frame gets the same draw whichever window of the
    frame asks for it, so a window sees exactly the noise the full frame would. Two splitmix64
    hashes of the pixel's index give two 53-bit uniforms, Box-Muller one normal.
    """
    y = np.arange(rows.start, rows.stop, dtype=np.uint64)[:, None]
    x = np.arange(cols.start, cols.stop, dtype=np.uint64)[None, :]
    counter = ((y << np.uint64(32)) | x) << np.uint64(1)
    base = _mix64(np.array([key], dtype=np.uint64) + _GOLDEN)
    u1 = ((_mix64(base ^ counter) >> np.uint64(11)).astype(np.float64) + 0.5) / 2.0**53
    u2 = (_mix64(base ^ (counter | np.uint64(1))) >> np.uint64(11)).astype(np.float64) / 2.0**53
    return torch.from_numpy((np.sqrt(-2.0 * np.log(u1)) * np.cos(2.0 * np.pi * u2)).astype(np.float32))


def simulation_box(window: tuple[int, int, int, int], frame_hw: tuple[int, int], halo_px: int
                   ) -> tuple[int, int, int, int]:
    """The region simulated for `window` (x0, y0, x1, y1): grown by `halo_px` on every side, clipped
    to the frame, its top-left corner on an even pixel (the RGGB phase of the frame)."""
    x0, y0, x1, y1 = window
    x0, y0 = max(x0 - halo_px, 0) // 2 * 2, max(y0 - halo_px, 0) // 2 * 2
    return x0, y0, min(x1 + halo_px, frame_hw[1]), min(y1 + halo_px, frame_hw[0])


def sense_windows(lens: lenses.Lens, frames: list[Scene], windows: list[PlateWindow], seed: int, device: str
                  ) -> list[torch.Tensor]:
    """Sensor images (3,h,w) in [0,1], on the CPU, of each window of `frames`, equal to the full
    frame's simulation (`windows` = the whole frame) inside the window.

    Each window is simulated on its region grown by the PSF's radius plus 2 pixels (the bilinear
    demosaic reads 1 neighbour; 1 more keeps the Bayer phase when the corner moves to an even
    pixel); the lens sees the frame's own reflect padding at frame borders, and the sensor noise
    is `positional_normal` of the frame's `noise_key`, so a window and the full frame draw the
    same noise at the same pixel. Equal means: the noise-free irradiance agrees to float rounding
    (the FFT of a different size), so after 10-bit quantization a rare pixel may differ by one level.
    """
    halo = lens.geometry.psf_size_px // 2 + 2
    out = []
    with torch.no_grad():
        for w in windows:
            frame = frames[w.frame]
            hw = frame.image.shape[:2]
            sx0, sy0, sx1, sy1 = simulation_box(w.box_xyxy, hw, halo)
            region = torch.from_numpy(np.ascontiguousarray(frame.image[sy0:sy1, sx0:sx1])).permute(2, 0, 1)[None]
            eps = positional_normal(noise_key(seed, frame), range(sy0, sy1), range(sx0, sx1))[None, None]
            sensor = lens.sensor(lens.irradiance(region.to(device)), eps=eps.to(device))
            x0, y0, x1, y1 = w.box_xyxy
            out.append(sensor[0, :, y0 - sy0:y1 - sy0, x0 - sx0:x1 - sx0].cpu())
    return out


def train_pairs_factory(lens: lenses.Lens, cfg: RunConfig, seed: int
                        ) -> Callable[[], Iterator[tuple[torch.Tensor, torch.Tensor]]]:
    """A re-iterable source of (sensor, sharp) batches, each (B,3,h,w) in [0,1] with (h, w) the
    profile's training crop: one random crop of each TRAIN scene, for attackers that fit."""
    p = cfg.profile
    cached: list[torch.Tensor] = []

    def pairs() -> Iterator[tuple[torch.Tensor, torch.Tensor]]:
        if not cached:
            cached.append(to_tensor(load_scenes(cfg.scenes, "train", p.n_train, p.image_size, seed)))
        (crops,) = random_crops([cached[0]], p.train_crop, torch.Generator().manual_seed(seed + 1))
        gen = torch.Generator(device=cfg.device).manual_seed(seed + 1)
        for sharp in batches(crops, p.batch_size):
            sharp = sharp.to(cfg.device)
            with torch.no_grad():
                yield lens(sharp, generator=gen), sharp

    return pairs
