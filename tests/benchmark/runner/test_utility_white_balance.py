"""The lens's utility network segments white-balanced sensor images (Lens.white_balance)."""

import dataclasses

import torch

import lenses
from benchmark.store.profiles import get_profile
from benchmark.runner.config import RunConfig
from benchmark.runner.utility_measure import segmenter
from benchmark.codesign.utility.segformer import build_segformer


def test_a_lens_segmenter_white_balances_its_input_first(tmp_path):
    torch.manual_seed(0)
    profile = dataclasses.replace(get_profile("smoke"), image_size=(64, 64), train_crop=(32, 32), batch_size=2)
    cfg = RunConfig(["ideal"], None, "synthetic", profile, [0], cache_dir=tmp_path)
    lens = lenses.load("ideal")
    net = build_segformer("tiny").eval()
    sensor = torch.rand(2, 3, 64, 64) * lens.gain().view(1, 3, 1, 1)  # a tinted sensor image
    for layer in net.modules():  # random weights give one class everywhere; spread the logits out
        if isinstance(layer, torch.nn.Conv2d):
            layer.weight.data *= 8
    balanced = segmenter(net, cfg, lens)
    plain = segmenter(net, cfg)
    assert torch.equal(balanced(sensor), plain(lens.white_balance(sensor)))
    assert not torch.equal(balanced(sensor), plain(sensor))
    assert balanced.describe()["white_balance"] == "divide-by-known-sensor-gain"
    assert plain.describe()["white_balance"] == "none"
