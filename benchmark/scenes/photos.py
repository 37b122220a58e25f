"""The ``photos`` scene set: colour photographs bundled with scikit-image, for restoration metrics.

Splits are a fixed partition of the photo list (``PHOTO_SPLITS``): test = astronaut, coffee,
stereo_motorcycle (left view); val = chelsea, rocket; train = immunohistochemistry,
hubble_deep_field, retina. Each photo is resized to cover ``size`` and centre-cropped; when
``n`` exceeds the split's photos, later passes over the list take seeded random zoomed crops.
The sRGB values are used as they are (treated as linear radiance), as the paper does with
Cityscapes images. No labels (all 255) and no plates.
"""

from __future__ import annotations

from collections.abc import Callable
from functools import lru_cache

import numpy as np
import skimage.data
from PIL import Image

PHOTO_SPLITS: dict[str, tuple[str, ...]] = {
    "train": ("immunohistochemistry", "hubble_deep_field", "retina"),
    "val": ("chelsea", "rocket"),
    "test": ("astronaut", "coffee", "stereo_motorcycle"),
}


@lru_cache(maxsize=16)
def _photo(name: str) -> Image.Image:
    loader: Callable[[], object] = getattr(skimage.data, name)
    data = loader()
    pixels = data[0] if isinstance(data, tuple) else data  # stereo_motorcycle -> (left, right, disparity)
    return Image.fromarray(np.asarray(pixels)[..., :3])


def load_photo(split: str, index: int, size: tuple[int, int], rng: np.random.Generator) -> tuple[str, np.ndarray]:
    """Return (photo name, (H, W, 3) float32 image in [0, 1]) for scene ``index`` of ``split``.

    The first pass over the split is centre crops; later passes zoom by 1..1.6x and crop at a
    position drawn from ``rng``.
    """
    names = PHOTO_SPLITS[split]
    name = names[index % len(names)]
    photo = _photo(name)
    height, width = size
    zoom = 1.0 if index < len(names) else rng.uniform(1.0, 1.6)
    scale = zoom * max(height / photo.height, width / photo.width)
    resized_w, resized_h = max(width, round(photo.width * scale)), max(height, round(photo.height * scale))
    fy, fx = (0.5, 0.5) if index < len(names) else rng.uniform(0.0, 1.0, size=2)
    top, left = round(fy * (resized_h - height)), round(fx * (resized_w - width))
    resized = photo.resize((resized_w, resized_h), Image.Resampling.LANCZOS, reducing_gap=3.0)
    crop = resized.crop((left, top, left + width, top + height))
    return name, np.asarray(crop, dtype=np.float32) / 255.0
