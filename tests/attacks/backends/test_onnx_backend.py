"""ONNX Runtime inference gives the torch output (max abs diff <= 1e-4)."""

from __future__ import annotations

import pytest
import torch

from attacks.networks import RED10, NAFNet
from attacks.backends.onnx_runtime import InferenceEngine


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


def test_batches_are_bounded_by_pixels_and_give_the_one_at_a_time_output():
    engine = InferenceEngine(_red10(), "onnx", export_hw=(32, 32), batch_pixels=3 * 32 * 48)
    x = torch.rand(7, 3, 32, 48, generator=torch.Generator().manual_seed(3))
    assert [b.shape[0] for b in engine.batches(x)] == [3, 3, 1]
    assert [b.shape[0] for b in engine.batches(torch.rand(2, 3, 64, 96))] == [1, 1]  # never fewer than one
    one_at_a_time = torch.cat([engine(image[None]) for image in x])
    assert (engine(x) - one_at_a_time).abs().max() <= 1e-5


def _broken_export() -> bytes:
    raise RuntimeError("operator not supported")


def test_a_failed_export_falls_back_to_torch_only_when_allowed(caplog):
    model = _red10()
    x = torch.rand(1, 3, 16, 16)
    for engine in (InferenceEngine(model, "auto", exporter=_broken_export),
                   InferenceEngine(model, "onnx", exporter=_broken_export, fallback=True)):
        assert engine.backend == "torch"
        assert "operator not supported" in engine.describe()["fallback_reason"]
        assert torch.equal(engine(x), InferenceEngine(model, "torch")(x))
    assert "operator not supported" in caplog.text
    with pytest.raises(RuntimeError, match="operator not supported"):
        InferenceEngine(model, "onnx", exporter=_broken_export)


def test_describe_records_the_choice_of_auto():
    engine = InferenceEngine(_red10(), "auto", export_hw=(32, 32))
    engine(torch.rand(1, 3, 32, 32))
    described = engine.describe()
    assert described["requested"] == "auto" and described["fallback_reason"] is None
    assert described["backend"] == min(engine.timings_s, key=engine.timings_s.get)
    assert "timings_s" not in described  # settings must hash the same run to run


def test_auto_times_each_architecture_and_shape_once_per_process(monkeypatch):
    from attacks.backends import onnx_runtime as onnx_backend

    timed = []

    def fake_time(run, x, repeats=1):
        timed.append(tuple(x.shape))
        return 2.0 if run.__class__.__name__ == "OnnxModel" else 1.0

    monkeypatch.setattr(onnx_backend, "_TIMINGS_S", {})
    monkeypatch.setattr(onnx_backend, "_time", fake_time)
    first, same = InferenceEngine(_red10(), "auto", export_hw=(32, 32)), InferenceEngine(_red10(), "auto", export_hw=(32, 32))
    wider = InferenceEngine(RED10(width=16).eval(), "auto", export_hw=(32, 32))
    x = torch.rand(1, 3, 32, 48)
    first(x)
    same(x)
    assert timed == [(1, 3, 32, 48)] * 2  # both backends of the first engine, none for the second
    assert same.backend == first.backend == "torch" and same.timings_s == first.timings_s
    same(torch.rand(1, 3, 16, 48))  # decided for good: a later shape is not timed
    wider(x)
    InferenceEngine(_red10(), "auto", export_hw=(32, 32))(torch.rand(1, 3, 16, 16))
    assert timed == [(1, 3, 32, 48)] * 4 + [(1, 3, 16, 16)] * 2  # another architecture, another shape
