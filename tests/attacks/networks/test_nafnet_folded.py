"""The NAFNet folded for inference computes what the trained NAFNet computes."""

import pytest
import torch

from attacks.networks.nafnet import NAFBlock, NAFNet
from attacks.networks.nafnet_folded import FoldedNAFBlock, fold_for_inference
from attacks.backends.onnx_runtime import InferenceEngine
from attacks.training.restorer_training import RestorerBudget
from benchmark.store.profiles import PROFILES

TINY = dict(width=8, middle_blk_num=1, enc_blk_nums=(1, 2), dec_blk_nums=(2, 1))


def _randomized(model: torch.nn.Module, seed: int = 0) -> torch.nn.Module:
    """Random values in every parameter (a fresh NAFNet's beta = gamma = 0 would make each block an
    identity, and non-trivial norm affines are what the folding moves)."""
    g = torch.Generator().manual_seed(seed)
    with torch.no_grad():
        for name, p in model.named_parameters():
            p.copy_(0.1 * torch.randn(p.shape, generator=g) + (1.0 if name.endswith("weight") and p.dim() == 1 else 0.0))
    return model.eval()


@pytest.mark.parametrize("hw", [(32, 48), (37, 53)])
def test_folded_nafnet_equals_the_original(hw):
    model = _randomized(NAFNet(**TINY))
    before = {k: v.clone() for k, v in model.state_dict().items()}
    folded = fold_for_inference(model)
    x = torch.rand(2, 3, *hw, generator=torch.Generator().manual_seed(1))
    with torch.no_grad():
        want, got = model(x), folded(x)
    assert got.shape == want.shape
    assert torch.allclose(got, want, atol=1e-5, rtol=0), float((got - want).abs().max())
    # Every block was replaced in the copy, none in the original, whose weights are untouched.
    assert not any(isinstance(m, NAFBlock) for m in folded.modules())
    assert sum(isinstance(m, FoldedNAFBlock) for m in folded.modules()) == sum(
        isinstance(m, NAFBlock) for m in model.modules()) == 7
    assert all(torch.equal(v, before[k]) for k, v in model.state_dict().items())


def test_folded_block_needs_no_slice_and_no_norm_affine():
    block = _randomized(NAFBlock(4))
    folded = FoldedNAFBlock(block)
    x = torch.randn(1, 4, 9, 11)
    with torch.no_grad():
        assert torch.allclose(folded(x), block(x), atol=1e-5)
    names = {n for n, _ in folded.named_parameters()}
    assert not any(n.startswith(("norm", "beta", "gamma")) for n in names)
    assert folded.conv1a.out_channels == folded.conv1b.out_channels == 4


def test_folded_quick_nafnet_through_onnx_runtime_matches_the_torch_original():
    model = _randomized(RestorerBudget.from_budget(PROFILES["quick"].attack_budget()).build_nafnet(), seed=3)
    x = torch.rand(1, 3, 64, 96, generator=torch.Generator().manual_seed(2))
    with torch.no_grad():
        want = model(x)
    got = InferenceEngine(fold_for_inference(model), "onnx")(x)
    assert torch.allclose(got, want, atol=1e-4, rtol=0), float((got - want).abs().max())


def test_folded_network_stays_on_the_networks_device():
    """Folding builds new convolutions: they must live where the network does (a NAFNet on a GPU once
    folded into CPU weights and failed at restore). The meta device stands in for a GPU here."""
    net = NAFNet(3, 8, 1, (1,), (1,)).to("meta")
    folded = fold_for_inference(net)
    assert {p.device.type for p in folded.parameters()} == {"meta"}
    assert {p.dtype for p in folded.parameters()} == {torch.float32}
