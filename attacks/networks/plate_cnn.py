"""A small CNN that reads a plate crop as one classifier per character slot.

Input: the crop of ``attacks.readers.plates.plate_sim.plate_crops`` (B, 3, 24, 96), each channel
standardised. Four stages of two 3x3 convolutions (BatchNorm, ReLU), the first three followed by
2x2 max pooling and the last by pooling the height away; the (B, C, 3, 12) map is flattened and
one linear layer gives every slot's logits over that slot's alphabet (26 letters or 10 digits), so
each slot sees the whole plate (a proportional font puts glyph k where the others' widths put it).
At the reader's width 16: 0.46 M parameters, 25 M multiply-adds per plate and view.
"""

from __future__ import annotations

import torch
from torch import Tensor, nn

__all__ = ["PlateCNN"]


def _stage(c_in: int, c_out: int) -> list[nn.Module]:
    return [nn.Conv2d(c_in, c_out, 3, padding=1, bias=False), nn.BatchNorm2d(c_out), nn.ReLU(inplace=True),
            nn.Conv2d(c_out, c_out, 3, padding=1, bias=False), nn.BatchNorm2d(c_out), nn.ReLU(inplace=True)]


class PlateCNN(nn.Module):
    """Plate crop (B, 3, 24, 96) -> per-slot logits, a list of (B, len(alphabet)) tensors.

    Args:
        alphabet_sizes: The number of symbols of each slot, in order (e.g. 26, 26, 10, 10, 10, 26, 26).
        width: Channels of the first stage (doubled twice, then kept).
        dropout: Dropout before the slot classifiers.
    """

    def __init__(self, alphabet_sizes: tuple[int, ...], width: int = 16, dropout: float = 0.2) -> None:
        super().__init__()
        self.alphabet_sizes = tuple(alphabet_sizes)
        c1, c2, c3 = width, 2 * width, 4 * width
        self.features = nn.Sequential(
            *_stage(3, c1), nn.MaxPool2d(2),            # 12 x 48
            *_stage(c1, c2), nn.MaxPool2d(2),           # 6 x 24
            *_stage(c2, c3), nn.MaxPool2d((2, 2)),      # 3 x 12
            *_stage(c3, c3),
        )
        self.dropout = nn.Dropout(dropout)
        self.head = nn.Linear(c3 * 3 * 12, sum(self.alphabet_sizes))

    def forward(self, x: Tensor) -> list[Tensor]:
        logits = self.head(self.dropout(self.features(x).flatten(1)))
        return list(torch.split(logits, list(self.alphabet_sizes), dim=1))
