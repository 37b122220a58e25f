"""Bilinear resizing (align_corners=False) as two small matrix products, for the steps that train SegFormer.

SegFormer's decode head resizes each of its four stages' maps to the first stage's size, and
`segment_logits` resizes the logits to the image: with ``F.interpolate`` on the CPU the backward of
those resizes (a scatter kernel) and the copies around it took about a fifth of a quick co-design
step (docs/history.md). The same resize is
``A_h @ x @ A_w^T`` with fixed (out, in) weight matrices of two non-zeros a row, whose forward and
backward are dense matrix products; the first stage, already at the target size, is not resized at all
(``F.interpolate`` copies it). tests/speed/test_training_step_speed.py times both in one run; the
training steps are faster with the products (docs/costs.md; docs/history.md).

The weights are torch's own (``area_pixel_compute_source_index`` with ``align_corners=False``: source
``(dst + 0.5) * in / out - 0.5``, clamped at 0, both neighbours' lambdas), so the result equals
``F.interpolate``'s up to float rounding (tests/benchmark/codesign/test_bilinear.py); only the order of the
additions differs. Inference keeps ``F.interpolate`` (`resize_for_training` falls back to it when no
gradient flows), so every evaluated number stays bit for bit what it was.
"""

from __future__ import annotations

from functools import lru_cache

import torch
import torch.nn.functional as F

__all__ = ["bilinear_weights", "resize_bilinear", "resize_for_training"]


@lru_cache(maxsize=64)
def _weights_cpu(n_in: int, n_out: int) -> torch.Tensor:
    scale = torch.tensor(n_in / n_out, dtype=torch.float32)
    dst = torch.arange(n_out, dtype=torch.float32)
    src = (scale * (dst + 0.5) - 0.5).clamp_min(0.0)
    i0 = src.to(torch.int64).clamp_max(n_in - 1)
    i1 = torch.where(i0 < n_in - 1, i0 + 1, i0)
    lam1 = (src - i0.to(torch.float32)).clamp(0.0, 1.0)
    weights = torch.zeros(n_out, n_in, dtype=torch.float32)
    rows = torch.arange(n_out)
    weights.index_put_((rows, i0), 1.0 - lam1, accumulate=True)
    weights.index_put_((rows, i1), lam1, accumulate=True)
    return weights


def bilinear_weights(n_in: int, n_out: int, dtype: torch.dtype = torch.float32,
                     device: torch.device | str = "cpu") -> torch.Tensor:
    """(n_out, n_in): row j holds the weights of output sample j on the input samples (two non-zeros
    summing to 1; an identity for n_in == n_out)."""
    if n_in < 1 or n_out < 1:
        raise ValueError(f"sizes must be >= 1, got n_in={n_in}, n_out={n_out}")
    return _weights_cpu(n_in, n_out).to(dtype=dtype, device=device)


def resize_bilinear(x: torch.Tensor, size: tuple[int, int] | torch.Size) -> torch.Tensor:
    """``F.interpolate(x, size, mode="bilinear", align_corners=False)`` for x (B, C, H, W) as two matrix
    products (``x`` itself where it is already ``size``): the same values up to float rounding,
    differentiable, with a backward of matrix products. Like ``F.interpolate`` it keeps a channels-last
    input channels-last (the decode head's maps are: the dropout after them draws its mask in memory
    order, so the layout decides which values it drops)."""
    h_out, w_out = int(size[0]), int(size[1])
    batch, channels, h_in, w_in = x.shape
    if (h_in, w_in) == (h_out, w_out):
        return x
    w_weights = bilinear_weights(w_in, w_out, x.dtype, x.device) if w_in != w_out else None
    h_weights = bilinear_weights(h_in, h_out, x.dtype, x.device) if h_in != h_out else None
    if x.is_contiguous(memory_format=torch.channels_last) and not x.is_contiguous():
        nhwc = x.permute(0, 2, 3, 1)
        if w_weights is not None:  # (W', W) @ (B, H, W, C): along the width
            nhwc = w_weights @ nhwc
        if h_weights is not None:  # (H', H) @ (B, H, W' C): along the height
            nhwc = (h_weights @ nhwc.reshape(batch, h_in, w_out * channels)).reshape(batch, h_out, w_out, channels)
        return nhwc.permute(0, 3, 1, 2)
    if w_weights is not None:
        x = x @ w_weights.T
    if h_weights is not None:
        x = h_weights @ x
    return x


def resize_for_training(x: torch.Tensor, size: tuple[int, int] | torch.Size) -> torch.Tensor:
    """`resize_bilinear` when a gradient flows through ``x`` (a training step), else ``F.interpolate``
    (bilinear, align_corners=False), so that inference is unchanged to the bit."""
    if torch.is_grad_enabled() and x.requires_grad:
        return resize_bilinear(x, size)
    return F.interpolate(x, size=tuple(size), mode="bilinear", align_corners=False)
