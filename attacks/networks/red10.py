"""RED10: the 10-layer RED-Net (Mao et al. 2016) as the co-design deblurring adversary.

Following the privacy-lens paper (Sec. 3.2) this variant has no skip connections between the
convolution and deconvolution halves: an encoder of five 3x3 convolutions, four of them with
stride 2 (resolution / 16), and a decoder of five transposed convolutions, four of them with
stride 2, back to full resolution.

Everything is out-of-place (no ``inplace=True`` ReLU), and only ops with second derivatives are
used, because the gradient-penalty scheme differentiates d L_deb / d theta_opt again.

The co-design adversary uses two options that depart from the paper's RED10, because without
them it never beats the trivial attack (measured on the smoke profile's starting lens, width 8,
600 Adam steps: 18.5 dB against 24.8 dB for the white-balanced sensor image; with a residual
alone it stays at 24.81 dB, since nothing full-resolution passes the 1/16 bottleneck):

- ``skips``: RED-Net's own symmetric skip connections (Mao et al. 2016): each encoder feature map
  is added to the decoder's at the same resolution, before its ReLU. No parameters are added, so
  the state dict is the same as without.
- ``residual``: the network sees the white-balanced input x / input_gain (``input_gain`` a
  persistent buffer, set to the lens's per-channel sensor gain) and predicts a correction to it;
  the last layer starts at zero, so an untrained network returns the white-balanced image.
  The output is not squashed (no sigmoid): scorers clamp it to [0, 1].

With both, 100 steps beat the white-balanced image by 1.35 dB on the same data.
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
        skips: add each encoder feature map to the decoder's at the same resolution (RED-Net's
            symmetric skips; the paper's RED10 has none).
        residual: predict a correction to the white-balanced input x / input_gain instead of the
            image through a sigmoid (output then unbounded; clamp it to [0, 1] to score it).

    Attributes:
        encoder: conv layers; its output is the bottleneck at resolution (H/16, W/16).
        decoder: transposed-conv layers back to (H, W).
    """

    downsampling = 16
    input_gain: torch.Tensor

    def __init__(self, width: int = 64, in_channels: int = 3, skips: bool = False, residual: bool = False) -> None:
        super().__init__()
        self.skips, self.residual = skips, residual
        encoder: list[nn.Module] = [nn.Conv2d(in_channels, width, kernel_size=3, padding=1), nn.ReLU()]
        for _ in range(4):
            encoder += [nn.Conv2d(width, width, kernel_size=3, stride=2, padding=1), nn.ReLU()]
        decoder: list[nn.Module] = []
        for _ in range(4):
            # kernel 4, stride 2, padding 1 doubles the size exactly: (n - 1) * 2 - 2 + 4 = 2n.
            decoder += [nn.ConvTranspose2d(width, width, kernel_size=4, stride=2, padding=1), nn.ReLU()]
        last = nn.ConvTranspose2d(width, in_channels, kernel_size=3, padding=1)
        decoder.append(last)
        self.encoder = nn.Sequential(*encoder)
        self.decoder = nn.Sequential(*decoder)
        if residual:
            self.register_buffer("input_gain", torch.ones(in_channels))
            nn.init.zeros_(last.weight)
            nn.init.zeros_(last.bias)  # type: ignore[arg-type]  # ConvTranspose2d(bias=True) has one

    def forward(self, x: torch.Tensor) -> torch.Tensor:
        _, _, h, w = x.shape
        if self.residual:
            x = x / self.input_gain.view(1, -1, 1, 1)
        pad_h = -h % self.downsampling
        pad_w = -w % self.downsampling
        padded = F.pad(x, (0, pad_w, 0, pad_h), mode="replicate") if pad_h or pad_w else x
        z = self._skipped(padded) if self.skips else self.decoder(self.encoder(padded))
        z = z[:, :, :h, :w]
        return x + z if self.residual else torch.sigmoid(z)

    def _skipped(self, x: torch.Tensor) -> torch.Tensor:
        """Encoder then decoder, each encoder output added to the decoder's input of its resolution."""
        features = []
        for conv, relu in zip(self.encoder[0::2], self.encoder[1::2]):
            x = relu(conv(x))
            features.append(x)
        z = features.pop()
        for deconv, relu in zip(self.decoder[0:-1:2], self.decoder[1::2]):
            z = relu(deconv(z) + features.pop())
        return self.decoder[-1](z)
