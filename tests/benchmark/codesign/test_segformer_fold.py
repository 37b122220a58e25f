"""The folded SegFormer head (benchmark/codesign/utility/segformer_onnx.py) computes the head as trained: the same
logits as ``segment_logits`` to float rounding, with trained-like batch-norm statistics, at any size."""

from __future__ import annotations

import pytest
import torch

from benchmark.codesign.utility.segformer import build_segformer, segment_logits
from benchmark.codesign.utility.segformer_onnx import FoldedSegformerLogits


def _net(variant: str) -> torch.nn.Module:
    torch.manual_seed(0)
    net = build_segformer(variant).eval()
    norm = net.decode_head.batch_norm
    with torch.no_grad():  # statistics far from the identity, so a misplaced scale or shift shows
        norm.running_mean.uniform_(-1.0, 1.0)
        norm.running_var.uniform_(0.2, 3.0)
        norm.weight.uniform_(0.5, 2.0)
        norm.bias.uniform_(-1.0, 1.0)
    return net


@pytest.mark.parametrize("variant", ["tiny", "b0"])
@pytest.mark.parametrize("shape", [(2, 3, 64, 64), (1, 3, 45, 70)])
def test_folded_head_gives_the_logits_of_the_trained_head(variant, shape):
    net = _net(variant)
    x = torch.rand(*shape, generator=torch.Generator().manual_seed(1))
    with torch.no_grad():
        reference = segment_logits(net, x)
        folded = FoldedSegformerLogits(net).eval()(x)
    assert folded.shape == reference.shape
    assert (folded - reference).abs().max() <= 1e-4 * max(1.0, float(reference.abs().max()))


def test_folded_head_is_a_snapshot_of_the_weights():
    net = _net("tiny")
    folded = FoldedSegformerLogits(net).eval()
    x = torch.rand(1, 3, 64, 64, generator=torch.Generator().manual_seed(2))
    with torch.no_grad():
        before = folded(x)
        net.decode_head.linear_fuse.weight.mul_(2.0)
        assert torch.equal(folded(x), before)
        reference = segment_logits(net, x)
        assert (FoldedSegformerLogits(net).eval()(x) - reference).abs().max() <= 1e-4 * float(reference.abs().max())


def test_a_head_that_is_not_segformer_s_is_refused():
    net = _net("tiny")
    net.decode_head.linear_fuse.bias = torch.nn.Parameter(torch.zeros(net.decode_head.linear_fuse.out_channels))
    with pytest.raises(ValueError, match="all-MLP decode head"):
        FoldedSegformerLogits(net)
