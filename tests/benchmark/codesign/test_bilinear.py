"""Bilinear resizing by matrix products against torch's F.interpolate, and SegFormer's decode head using it."""

from __future__ import annotations

import pytest
import torch
import torch.nn.functional as F
from transformers import SegformerForSemanticSegmentation
from transformers.models.segformer.modeling_segformer import SegformerDecodeHead

from benchmark.codesign.utility.bilinear import bilinear_weights, resize_bilinear, resize_for_training
from benchmark.codesign.utility.segformer import TrainingDecodeHead, build_segformer, segment_logits

SIZES = [((4, 4), (32, 32)), ((8, 16), (32, 64)), ((13, 7), (50, 25)), ((25, 25), (100, 100)),
         ((32, 32), (32, 32)), ((9, 12), (9, 40)), ((40, 30), (17, 11)), ((1, 5), (6, 5))]


@pytest.mark.parametrize("layout", [torch.contiguous_format, torch.channels_last])
@pytest.mark.parametrize(("size_in", "size_out"), SIZES)
def test_resize_equals_torch_interpolate_forward_and_backward(size_in, size_out, layout):
    """Values and gradients within float rounding of F.interpolate, and the same memory layout."""
    g = torch.Generator().manual_seed(0)
    x = torch.randn(2, 3, *size_in, generator=g).contiguous(memory_format=layout)
    upstream = torch.randn(2, 3, *size_out, generator=g)
    xa, xb = x.clone().requires_grad_(True), x.clone().requires_grad_(True)
    ours = resize_bilinear(xa, size_out)
    ref = F.interpolate(xb, size=size_out, mode="bilinear", align_corners=False)
    torch.testing.assert_close(ours, ref, rtol=1e-5, atol=1e-5)
    assert ours.stride() == ref.stride() or size_in == size_out
    (ours * upstream).sum().backward()
    (ref * upstream).sum().backward()
    torch.testing.assert_close(xa.grad, xb.grad, rtol=1e-5, atol=1e-5)


def test_weights_rows_sum_to_one_and_identity_at_equal_size():
    for n_in, n_out in [(4, 32), (13, 50), (40, 17), (7, 7)]:
        w = bilinear_weights(n_in, n_out)
        assert w.shape == (n_out, n_in)
        torch.testing.assert_close(w.sum(dim=1), torch.ones(n_out))
        assert int((w != 0).sum(dim=1).max()) <= 2
    assert torch.equal(bilinear_weights(7, 7), torch.eye(7))
    with pytest.raises(ValueError, match="sizes must be >= 1"):
        bilinear_weights(0, 4)


def test_resize_gradient_check_in_double():
    x = torch.randn(1, 2, 5, 6, dtype=torch.float64, requires_grad=True)
    assert torch.autograd.gradcheck(lambda t: resize_bilinear(t, (11, 9)), (x,))


def test_resize_for_training_is_torch_interpolate_to_the_bit_without_a_gradient():
    x = torch.randn(2, 19, 8, 16)
    ref = F.interpolate(x, size=(32, 64), mode="bilinear", align_corners=False)
    with torch.no_grad():
        assert torch.equal(resize_for_training(x.requires_grad_(True), (32, 64)), ref)
    assert torch.equal(resize_for_training(x.detach(), (32, 64)), ref)


def test_build_segformer_keeps_initialisation_and_swaps_only_the_head_class():
    torch.manual_seed(3)
    ours = build_segformer("tiny")
    torch.manual_seed(3)
    plain = SegformerForSemanticSegmentation(ours.config)
    assert type(ours.decode_head) is TrainingDecodeHead
    assert isinstance(ours.decode_head, SegformerDecodeHead)
    theirs = plain.state_dict()
    assert ours.state_dict().keys() == theirs.keys()
    assert all(torch.equal(v, theirs[k]) for k, v in ours.state_dict().items())


@pytest.mark.parametrize("variant", ["tiny", "b0"])
def test_training_decode_head_matches_transformers_forward_and_gradients(variant):
    torch.manual_seed(0)
    net = build_segformer(variant).train()
    images = torch.rand(2, 3, 64, 96)

    def step(head_class: type) -> tuple[torch.Tensor, list[torch.Tensor]]:
        net.decode_head.__class__ = head_class
        net.zero_grad()
        torch.manual_seed(1)  # the same dropout mask both ways
        logits = segment_logits(net, images)
        logits.square().mean().backward()
        return logits.detach(), [p.grad.clone() for p in net.parameters() if p.grad is not None]

    ours, ours_grads = step(TrainingDecodeHead)
    ref, ref_grads = step(SegformerDecodeHead)
    torch.testing.assert_close(ours, ref, rtol=1e-5, atol=1e-5)
    assert len(ours_grads) == len(ref_grads)
    for a, b in zip(ours_grads, ref_grads):
        torch.testing.assert_close(a, b, rtol=1e-4, atol=1e-6)


def test_training_decode_head_is_the_original_to_the_bit_in_inference():
    torch.manual_seed(0)
    net = build_segformer("tiny").eval()
    images = torch.rand(2, 3, 64, 96)
    with torch.no_grad():
        ours = segment_logits(net, images)
        net.decode_head.__class__ = SegformerDecodeHead
        ref = segment_logits(net, images)
    assert torch.equal(ours, ref)
