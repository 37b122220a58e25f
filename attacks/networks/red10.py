"""RED10: the 10-layer RED-Net (Mao et al. 2016) as the co-design deblurring adversary.

Following the privacy-lens paper (Sec. 3.2) this variant has no skip connections between the
convolution and deconvolution halves: an encoder of five 3x3 convolutions, four of them with
stride 2 (resolution / 16), and a decoder of five transposed convolutions, four of them with
stride 2, back to full resolution.

Everything is out-of-place (no ``inplace=True`` ReLU), and only ops with second derivatives are
used, because the gradient-penalty scheme differentiates d L_deb / d theta_opt again.
"""

from __future__ import annotations

import torch
import torch.nn.functional as F
from torch import nn

__all__ = ["RED10"]


class RED10(nn.Module):
    """Encoder-decoder deblurring network: (B, in_channels, H, W) in [0, 1] -> same shape in (0, 1).

    Any H, W is accepted: the input is replicate-padded on the bottom/right to a multiple of 16
    (the total downsampling) and the output is cropped back. Replicate rather than zero padding,
    so the padded border looks like image content, not a black frame to be restored.

    The output goes through a sigmoid, so it lies in (0, 1) like the scene it restores; a clamp
    would do the same but zero the gradient of every saturated pixel, which starves both the
    adversary's training and the optics' gradient.

    Args:
        width: feature channels of every hidden layer (the paper's RED-Net uses 64).
        in_channels: image channels, also the output channels.

    Attributes:
        encoder: conv layers; its output is the bottleneck at resolution (H/16, W/16).
        decoder: transposed-conv layers back to (H, W).
    """

    downsampling = 16

    def __init__(self, width: int = 64, in_channels: int = 3) -> None:
        super().__init__()
        encoder: list[nn.Module] = [nn.Conv2d(in_channels, width, kernel_size=3, padding=1), nn.ReLU()]
        for _ in range(4):
            encoder += [nn.Conv2d(width, width, kernel_size=3, stride=2, padding=1), nn.ReLU()]
        decoder: list[nn.Module] = []
        for _ in range(4):
            # kernel 4, stride 2, padding 1 doubles the size exactly: (n - 1) * 2 - 2 + 4 = 2n.
            decoder += [nn.ConvTranspose2d(width, width, kernel_size=4, stride=2, padding=1), nn.ReLU()]
        decoder.append(nn.ConvTranspose2d(width, in_channels, kernel_size=3, padding=1))
        self.encoder = nn.Sequential(*encoder)
        self.decoder = nn.Sequential(*decoder)

    def forward(self, x: torch.Tensor) -> torch.Tensor:
        _, _, h, w = x.shape
        pad_h = -h % self.downsampling
        pad_w = -w % self.downsampling
        if pad_h or pad_w:
            x = F.pad(x, (0, pad_w, 0, pad_h), mode="replicate")
        y = torch.sigmoid(self.decoder(self.encoder(x)))
        return y[:, :, :h, :w]
