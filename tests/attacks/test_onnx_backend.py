"""ONNX Runtime inference gives the torch output (max abs diff <= 1e-4)."""

from __future__ import annotations

import pytest
import torch

from attacks.networks import RED10, NAFNet
from attacks.onnx_backend import InferenceEngine


def _nafnet() -> NAFNet:
    torch.manual_seed(0)
    model = NAFNet(width=8, middle_blk_num=1, enc_blk_nums=(1, 1), dec_blk_nums=(1, 1))
    # beta and gamma start at zero, which would make every block an identity; exercise them.
    with torch.no_grad():
        for name, p in model.named_parameters():
            if name.endswith(("beta", "gamma")):
                p.normal_(0, 0.5)
    return model.eval()


def _red10() -> RED10:
    torch.manual_seed(0)
    return RED10(width=8).eval()


@pytest.mark.parametrize("make", [_nafnet, _red10], ids=["nafnet", "red10"])
def test_onnx_matches_torch(make):
    model = make()
    torch_engine = InferenceEngine(model, "torch")
    onnx_engine = InferenceEngine(model, "onnx", export_hw=(32, 32))
    assert (torch_engine.backend, onnx_engine.backend) == ("torch", "onnx")
    # A size that is not a multiple of the networks' downsampling, and a batch: dynamic axes.
    x = torch.rand(2, 3, 45, 70, generator=torch.Generator().manual_seed(1))
    difference = (onnx_engine(x) - torch_engine(x)).abs().max()
    assert difference <= 1e-4


def test_auto_times_both_on_the_first_call_and_keeps_the_faster():
    engine = InferenceEngine(_nafnet(), "auto", export_hw=(32, 32))
    assert engine.backend == "auto"
    x = torch.rand(2, 3, 32, 48, generator=torch.Generator().manual_seed(2))
    first = engine(x)
    assert set(engine.timings_s) == {"torch", "onnx"}
    assert engine.backend == min(engine.timings_s, key=engine.timings_s.get)
    assert torch.equal(engine(x), first)  # decided once: later calls take the same path


def test_unknown_backend_is_rejected():
    with pytest.raises(ValueError, match="tensorrt"):
        InferenceEngine(_red10(), "tensorrt")
