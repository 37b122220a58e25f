"""NAFNet for inference: the same function as a trained ``NAFNet`` with fewer, cheaper operations.

Every ``NAFBlock`` becomes a ``FoldedNAFBlock``:

- the affine of each ``LayerNorm2d`` (``weight``, ``bias``) is folded into the 1x1 convolution that
  follows it (``conv1``, ``conv4``): ``W (g * n + b) + c = (W diag g) n + (W b + c)``;
- ``beta`` and ``gamma`` are folded into the convolution before them (``conv3``, ``conv5``);
- each convolution that feeds a ``SimpleGate`` is split into its two output halves (and the
  depthwise ``conv2`` with it), so the gate multiplies two tensors instead of slicing one.

The result equals the original up to float rounding (tests/attacks/networks/test_nafnet_folded.py: 1e-5 on
[0, 1] images). ONNX Runtime runs the folded network faster than the plain one, whose graph spends a
share of its time slicing for the gates (tests/speed/test_restorer_speed.py times both; docs/modelling.md,
"Restorer inference"). Its normalisation stays written out as operations: through ``layer_norm`` (two
transposes in the graph) the folded network ran slower (docs/history.md). Training uses the plain
``NAFNet``: folding is for a network whose weights no longer change.
"""

from __future__ import annotations

import copy

import torch
from torch import nn

from attacks.networks.nafnet import LayerNorm2d, NAFBlock, NAFNet

__all__ = ["FoldedNAFBlock", "fold_for_inference"]


def _normalise(x: torch.Tensor, eps: float) -> torch.Tensor:
    """``LayerNorm2d`` without its affine: each pixel's channel vector to zero mean, unit variance."""
    centred = x - x.mean(dim=1, keepdim=True)
    return centred / torch.sqrt(centred.pow(2).mean(dim=1, keepdim=True) + eps)


def _conv(weight: torch.Tensor, bias: torch.Tensor, padding: int = 0, groups: int = 1) -> nn.Conv2d:
    """A Conv2d holding ``weight`` (out, in/groups, k, k) and ``bias`` (out,)."""
    out_ch, in_per_group, k, _ = weight.shape
    conv = nn.Conv2d(in_per_group * groups, out_ch, kernel_size=k, padding=padding, groups=groups,
                     device=weight.device, dtype=weight.dtype)  # where the network lives (a GPU, say)
    with torch.no_grad():
        conv.weight.copy_(weight)
        conv.bias = nn.Parameter(bias.detach().clone())
    return conv


def _bias(conv: nn.Conv2d) -> torch.Tensor:
    """``conv``'s bias, zeros where it has none."""
    return conv.bias if conv.bias is not None else conv.weight.new_zeros(conv.out_channels)


def _fold_norm(conv: nn.Conv2d, norm: LayerNorm2d) -> tuple[torch.Tensor, torch.Tensor]:
    """Weight and bias of the 1x1 ``conv`` applied after ``norm``'s affine."""
    w = conv.weight[:, :, 0, 0]
    return (w * norm.weight[None, :])[:, :, None, None], w @ norm.bias + _bias(conv)


def _scale(conv: nn.Conv2d, scale: torch.Tensor) -> nn.Conv2d:
    """``conv`` followed by a per-channel multiplication by ``scale`` (1, C, 1, 1)."""
    s = scale.reshape(-1)
    return _conv(conv.weight * s[:, None, None, None], _bias(conv) * s)


class FoldedNAFBlock(nn.Module):
    """A ``NAFBlock`` after folding (module docs): same input, same output."""

    def __init__(self, block: NAFBlock) -> None:
        super().__init__()
        with torch.no_grad():
            c = block.conv2.out_channels // 2
            w1, b1 = _fold_norm(block.conv1, block.norm1)
            self.conv1a, self.conv1b = _conv(w1[:c], b1[:c]), _conv(w1[c:], b1[c:])
            w2, b2 = block.conv2.weight, _bias(block.conv2)
            self.conv2a = _conv(w2[:c], b2[:c], padding=1, groups=c)
            self.conv2b = _conv(w2[c:], b2[c:], padding=1, groups=c)
            self.sca = copy.deepcopy(block.sca)
            self.conv3 = _scale(block.conv3, block.beta)
            w4, b4 = _fold_norm(block.conv4, block.norm2)
            f = block.conv4.out_channels // 2
            self.conv4a, self.conv4b = _conv(w4[:f], b4[:f]), _conv(w4[f:], b4[f:])
            self.conv5 = _scale(block.conv5, block.gamma)
        self.eps1, self.eps2 = block.norm1.eps, block.norm2.eps

    def forward(self, inp: torch.Tensor) -> torch.Tensor:
        n = _normalise(inp, self.eps1)
        x = self.conv2a(self.conv1a(n)) * self.conv2b(self.conv1b(n))
        y = inp + self.conv3(x * self.sca(x))
        n = _normalise(y, self.eps2)
        return y + self.conv5(self.conv4a(n) * self.conv4b(n))


def fold_for_inference(model: NAFNet) -> NAFNet:
    """A copy of ``model`` in eval mode with every ``NAFBlock`` replaced by its ``FoldedNAFBlock``;
    ``model`` itself is left as it is."""
    folded = copy.deepcopy(model).eval()
    for module in list(folded.modules()):
        for child_name, child in list(module.named_children()):
            if isinstance(child, NAFBlock):
                setattr(module, child_name, FoldedNAFBlock(child))
    return folded.eval()
