"""The one random-crop sampler of the project: aligned crops of images (and their labels).

It lives in ``attacks`` because that is the lowest layer that crops (the trained restorers crop
their (sensor, sharp) pairs); the benchmark (attackers' training pairs, co-design batches) uses
the same function. Offsets are even by default, so a Bayer-mosaicked image keeps its colour phase.
"""

from __future__ import annotations

from collections.abc import Sequence

import torch
from torch import Tensor

__all__ = ["random_crops"]


def random_crops(tensors: Sequence[Tensor], crop_hw: tuple[int, int], generator: torch.Generator, *,
                 n: int | None = None, even_offsets: bool = True, hflip: bool = False) -> list[Tensor]:
    """The same random crops from every tensor of ``tensors``.

    Args:
        tensors: Aligned tensors, each (N, ..., H, W) with the same N, H, W: images (N, 3, H, W),
            labels (N, H, W), ...
        crop_hw: (h, w) of each crop in pixels; at most (H, W).
        generator: CPU torch generator; the crops are a pure function of its state.
        n: Number of crops, each from an image drawn with replacement; None: one crop per image,
            in order.
        even_offsets: Offsets at even pixels (keeps a Bayer mosaic's colour phase).
        hflip: Mirror each crop left-right with probability 1/2 (not for asymmetric PSFs or
            plate text that must stay readable).

    Returns:
        One tensor per input, (n or N, ..., h, w), same dtype and device as the input.

    Raises:
        ValueError: The tensors disagree in N, H or W, or the crop is larger than the images.
    """
    if not tensors:
        raise ValueError("random_crops needs at least one tensor")
    count, height, width = tensors[0].shape[0], tensors[0].shape[-2], tensors[0].shape[-1]
    for t in tensors:
        if (t.shape[0], t.shape[-2], t.shape[-1]) != (count, height, width):
            raise ValueError(f"random_crops: tensors of shapes {[tuple(x.shape) for x in tensors]} are not aligned "
                             "(same N, H, W)")
    h, w = crop_hw
    if not (0 < h <= height and 0 < w <= width):
        raise ValueError(f"crop {crop_hw} does not fit the images ({height}, {width})")
    n_crops = count if n is None else n
    index = torch.arange(count) if n is None else torch.randint(count, (n_crops,), generator=generator)
    step = 2 if even_offsets else 1
    ys = torch.randint((height - h) // step + 1, (n_crops,), generator=generator) * step
    xs = torch.randint((width - w) // step + 1, (n_crops,), generator=generator) * step
    flips = (torch.rand(n_crops, generator=generator) < 0.5) if hflip else torch.zeros(n_crops, dtype=torch.bool)
    out = []
    for t in tensors:
        crops = [t[i, ..., y:y + h, x:x + w] for i, y, x in zip(index.tolist(), ys.tolist(), xs.tolist())]
        out.append(torch.stack([c.flip(-1) if f else c for c, f in zip(crops, flips.tolist())]))
    return out
