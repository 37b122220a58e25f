"""NAFNet image restorer (Chen et al. 2022, "Simple Baselines for Image Restoration").

The module and parameter names follow the official implementation
(megvii-research/NAFNet, ``basicsr/models/archs/NAFNet_arch.py``) so that an official
checkpoint's state dict loads with ``strict=True``: ``intro``, ``ending``,
``encoders.i.j.{norm1,conv1,conv2,sca.1,conv3,beta,norm2,conv4,conv5,gamma}``, ``downs.i``,
``middle_blks.j``, ``ups.i.0``, ``decoders.i.j``.

The published GoPro deblurring model is ``NAFNet(width=32, middle_blk_num=1,
enc_blk_nums=(1, 1, 1, 28), dec_blk_nums=(1, 1, 1, 1))`` (17.11 M parameters), which is the
default here.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from pathlib import Path
from typing import Any

import torch
import torch.nn.functional as F
from torch import nn

__all__ = ["LayerNorm2d", "SimpleGate", "NAFBlock", "NAFNet", "load_nafnet_checkpoint"]


class LayerNorm2d(nn.Module):
    """Layer normalisation over the channel dimension of a (B, C, H, W) tensor.

    Each pixel's C-vector is normalised to zero mean and unit (biased) variance, then scaled by
    ``weight`` and shifted by ``bias`` (both (C,)). The official code wraps this in a custom
    ``autograd.Function`` with a hand-written backward; here it is torch's fused ``layer_norm`` over
    the channels of a channels-last view, whose backward (and double backward) torch provides; training
    steps run faster through it than with the mean and variance written out as separate operations
    (docs/history.md). The output comes back in channels-last layout, which the convolutions after it
    take as it is.
    """

    def __init__(self, channels: int, eps: float = 1e-6) -> None:
        super().__init__()
        self.weight = nn.Parameter(torch.ones(channels))
        self.bias = nn.Parameter(torch.zeros(channels))
        self.eps = eps
        self.channels = channels  # a plain int, so an exported graph holds a constant normalised shape

    def forward(self, x: torch.Tensor) -> torch.Tensor:
        channels_last = F.layer_norm(x.permute(0, 2, 3, 1), (self.channels,), self.weight, self.bias, self.eps)
        return channels_last.permute(0, 3, 1, 2)


class SimpleGate(nn.Module):
    """Split the channels in two halves and multiply them: (B, 2C, H, W) -> (B, C, H, W)."""

    def forward(self, x: torch.Tensor) -> torch.Tensor:
        a, b = x.chunk(2, dim=1)
        return a * b


class NAFBlock(nn.Module):
    """Nonlinear-activation-free block: (B, C, H, W) -> (B, C, H, W).

    Spatial branch: norm1 -> conv1 (1x1, C->2C) -> conv2 (3x3 depthwise) -> SimpleGate ->
    simplified channel attention (``sca``: global average pool, 1x1 conv, multiply) ->
    conv3 (1x1, C->C), added back with the learnable per-channel scale ``beta``.
    Channel branch (FFN): norm2 -> conv4 (1x1, C->2C) -> SimpleGate -> conv5 (1x1), added back
    with ``gamma``. ``beta`` and ``gamma`` start at zero, so a fresh block is the identity.
    Dropout is left out: the official default rate is 0, where it is an identity.
    """

    def __init__(self, channels: int, dw_expand: int = 2, ffn_expand: int = 2) -> None:
        super().__init__()
        dw_channels = channels * dw_expand
        ffn_channels = channels * ffn_expand
        self.norm1 = LayerNorm2d(channels)
        self.conv1 = nn.Conv2d(channels, dw_channels, kernel_size=1)
        self.conv2 = nn.Conv2d(dw_channels, dw_channels, kernel_size=3, padding=1, groups=dw_channels)
        self.sg = SimpleGate()
        self.sca = nn.Sequential(
            nn.AdaptiveAvgPool2d(1),
            nn.Conv2d(dw_channels // 2, dw_channels // 2, kernel_size=1),
        )
        self.conv3 = nn.Conv2d(dw_channels // 2, channels, kernel_size=1)
        self.norm2 = LayerNorm2d(channels)
        self.conv4 = nn.Conv2d(channels, ffn_channels, kernel_size=1)
        self.conv5 = nn.Conv2d(ffn_channels // 2, channels, kernel_size=1)
        self.beta = nn.Parameter(torch.zeros(1, channels, 1, 1))
        self.gamma = nn.Parameter(torch.zeros(1, channels, 1, 1))

    def forward(self, inp: torch.Tensor) -> torch.Tensor:
        x = self.sg(self.conv2(self.conv1(self.norm1(inp))))
        x = self.conv3(x * self.sca(x))
        y = inp + x * self.beta
        x = self.conv5(self.sg(self.conv4(self.norm2(y))))
        return y + x * self.gamma


class NAFNet(nn.Module):
    """U-shaped NAFNet restorer: image (B, img_channel, H, W) -> restored image, same shape.

    Works on any H, W: the input is zero-padded on the bottom/right to a multiple of
    2**len(enc_blk_nums) and the output is cropped back. The output is ``input + residual``
    with no clamping; values are in the input's range (e.g. [0, 1]) up to the residual's
    overshoot, so clamp before computing metrics if needed.

    Args:
        img_channel: number of image channels (3 for RGB).
        width: channels after the intro conv; doubled at each of the downsamplings.
        middle_blk_num: NAFBlocks at the lowest resolution.
        enc_blk_nums: NAFBlocks per encoder level (one 2x2 stride-2 down conv after each).
        dec_blk_nums: NAFBlocks per decoder level (one 1x1 conv + PixelShuffle(2) up before
            each); must have the same length as ``enc_blk_nums``.
        guide_channels: Extra input channels after the image's (e.g. a second estimate of the same
            scene): the input is (B, img_channel + guide_channels, H, W), the output stays
            (B, img_channel, H, W), the image channels plus the residual. 0 is the plain NAFNet.
    """

    def __init__(
        self,
        img_channel: int = 3,
        width: int = 32,
        middle_blk_num: int = 1,
        enc_blk_nums: Sequence[int] = (1, 1, 1, 28),
        dec_blk_nums: Sequence[int] = (1, 1, 1, 1),
        guide_channels: int = 0,
    ) -> None:
        super().__init__()
        if len(enc_blk_nums) != len(dec_blk_nums):
            raise ValueError(
                f"enc_blk_nums {tuple(enc_blk_nums)} and dec_blk_nums {tuple(dec_blk_nums)} "
                "must have the same length (one decoder level per encoder level)"
            )
        self.img_channel = img_channel
        self.intro = nn.Conv2d(img_channel + guide_channels, width, kernel_size=3, padding=1)
        self.ending = nn.Conv2d(width, img_channel, kernel_size=3, padding=1)
        self.encoders = nn.ModuleList()
        self.downs = nn.ModuleList()
        self.ups = nn.ModuleList()
        self.decoders = nn.ModuleList()

        chan = width
        for num in enc_blk_nums:
            self.encoders.append(nn.Sequential(*[NAFBlock(chan) for _ in range(num)]))
            self.downs.append(nn.Conv2d(chan, 2 * chan, kernel_size=2, stride=2))
            chan *= 2
        self.middle_blks = nn.Sequential(*[NAFBlock(chan) for _ in range(middle_blk_num)])
        for num in dec_blk_nums:
            # 1x1 conv to 2C then PixelShuffle(2): (2C, H, W) -> (C/2, 2H, 2W).
            self.ups.append(nn.Sequential(nn.Conv2d(chan, 2 * chan, kernel_size=1, bias=False), nn.PixelShuffle(2)))
            chan //= 2
            self.decoders.append(nn.Sequential(*[NAFBlock(chan) for _ in range(num)]))
        self.padder_size = 2 ** len(self.encoders)

    def forward(self, inp: torch.Tensor) -> torch.Tensor:
        _, _, h, w = inp.shape
        pad_h = -h % self.padder_size
        pad_w = -w % self.padder_size
        inp = F.pad(inp, (0, pad_w, 0, pad_h))

        x = self.intro(inp)
        skips = []
        for encoder, down in zip(self.encoders, self.downs):
            x = encoder(x)
            skips.append(x)
            x = down(x)
        x = self.middle_blks(x)
        for decoder, up, skip in zip(self.decoders, self.ups, reversed(skips)):
            x = decoder(up(x) + skip)
        x = self.ending(x) + inp[:, : self.img_channel]
        return x[:, :, :h, :w]


def _read_state_dict(path: Path) -> Mapping[str, Any]:
    if path.suffix == ".safetensors":
        from safetensors.torch import load_file

        return load_file(str(path), device="cpu")
    # weights_only=True refuses arbitrary pickled objects: checkpoints come from third parties.
    return torch.load(path, map_location="cpu", weights_only=True)


def load_nafnet_checkpoint(path: str | Path, **arch: Any) -> NAFNet:
    """Build a NAFNet and load a local checkpoint into it strictly.

    Args:
        path: local ``.pth``/``.pt`` (read with ``torch.load(weights_only=True)``) or
            ``.safetensors`` file. The official release wraps the weights as
            ``{"params": state_dict}`` (read first, as BasicSR's loader does); ``params_ema``,
            ``state_dict`` and a bare state dict are accepted too, and a
            ``module.`` prefix left by DataParallel is stripped.
        **arch: keyword arguments of :class:`NAFNet` (defaults: the GoPro width-32 model).

    Returns:
        The NAFNet in eval mode, on the CPU.

    Raises:
        FileNotFoundError: ``path`` does not exist.
        ValueError: the file's keys do not match the architecture (names missing and
            unexpected keys) or its tensors have the wrong shapes.
    """
    path = Path(path)
    if not path.is_file():
        raise FileNotFoundError(f"NAFNet checkpoint {path} does not exist (expected a local .pth or .safetensors file)")
    raw = _read_state_dict(path)
    state = raw
    for wrapper in ("params", "params_ema", "state_dict"):
        if isinstance(raw, Mapping) and isinstance(raw.get(wrapper), Mapping):
            state = raw[wrapper]
            break
    state = {k.removeprefix("module."): v for k, v in state.items()}

    model = NAFNet(**arch)
    expected = set(model.state_dict())
    missing = sorted(expected - set(state))
    unexpected = sorted(set(state) - expected)
    if missing or unexpected:
        raise ValueError(
            f"NAFNet checkpoint {path} does not match NAFNet({arch}): "
            f"{len(missing)} missing keys {missing[:10]}, {len(unexpected)} unexpected keys {unexpected[:10]}; "
            "check width/middle_blk_num/enc_blk_nums/dec_blk_nums"
        )
    try:
        model.load_state_dict(state, strict=True)
    except RuntimeError as err:
        raise ValueError(f"NAFNet checkpoint {path} has tensors of the wrong shape for NAFNet({arch}): {err}") from err
    return model.eval()
