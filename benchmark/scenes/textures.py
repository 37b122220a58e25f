"""Noise tiles for surface texture, synthesised once per process and cropped at random offsets.

Three zero-mean, unit-std fields: ``grain`` (pixel-scale, asphalt and concrete), ``cloud``
(1/f fractal blotches: stains, sky, uneven lighting) and ``leaf`` (clumpy mid-scale pattern for
foliage and grass). Feature sizes of ``cloud`` and ``leaf`` scale with the image width, so a
scene looks alike at any resolution.
"""

from __future__ import annotations

from functools import lru_cache

import numpy as np

@lru_cache(maxsize=2)
def noise_tiles(size: tuple[int, int]) -> np.ndarray:
    """(3, 2H, 2W) float32 periodic noise tiles (grain, cloud, leaf) for images of ``size = (H, W)``.

    Cached per size (48 bytes per image pixel: 25 MB at 512 x 1024) and deterministic (fixed
    seed); per-scene variety comes from the crop offset.
    """
    height, width = size
    rng = np.random.default_rng(20240531)
    shape = (2 * height, 2 * width)
    fy = np.fft.fftfreq(shape[0])[:, None]
    fx = np.fft.rfftfreq(shape[1])[None, :]
    # Frequencies in cycles per image width, so textures scale with resolution.
    f = np.sqrt(fy**2 + fx**2) * width
    f[0, 0] = 1.0

    def shaped(amplitude: np.ndarray) -> np.ndarray:
        spectrum = np.fft.rfft2(rng.standard_normal(shape, dtype=np.float32)) * amplitude
        field = np.fft.irfft2(spectrum, s=shape)
        field -= field.mean()
        return (field / field.std()).astype(np.float32)

    grain = shaped(np.exp(-((f / width / 0.35) ** 2)))
    cloud = shaped(1.0 / (f**1.6 + 4.0**1.6))
    # Two bands of clumps (about 1/110 and 1/275 of the width), saturated into leafy blobs.
    leaf_band = np.exp(-(((f - 110.0) / 66.0) ** 2)) + 0.7 * np.exp(-(((f - 275.0) / 110.0) ** 2))
    leaf = np.tanh(1.5 * shaped(leaf_band))
    leaf = (leaf - leaf.mean()) / leaf.std()
    return np.stack([grain, cloud, leaf.astype(np.float32)])


def texture_crops(size: tuple[int, int], rng: np.random.Generator) -> np.ndarray:
    """(3, H, W) float32 crops of the noise tiles (grain, cloud, leaf), each at its own random offset."""
    height, width = size
    tiles = noise_tiles((height, width))
    return np.stack(
        [tile[oy : oy + height, ox : ox + width] for tile, oy, ox in
         zip(tiles, rng.integers(height, size=3), rng.integers(width, size=3))]
    )
