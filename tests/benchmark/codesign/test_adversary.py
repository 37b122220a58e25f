"""The co-design adversary starts strong: pre-trained on the starting lens until it beats the
white-balanced sensor image by MARGIN_DB (smoke profile), from a RED10 that starts at that image."""

import dataclasses

import pytest
import torch

from attacks.networks.red10 import RED10
from benchmark.codesign.adversary import MARGIN_DB, Probe, build_adversary, pretrain_adversary, white_balanced
from benchmark.codesign.codesigned_lenses import START_SPEC
from benchmark.codesign.coefficients import initial_coefficients
from benchmark.codesign.data import CropSampler
from benchmark.store.profiles import PROFILES
from lenses.lens import Lens
from lenses.spec import load_spec


def _start_lens() -> Lens:
    start = load_spec(START_SPEC)
    mask = dataclasses.replace(start.mask, zernike_um=initial_coefficients(start, 0))
    return Lens(dataclasses.replace(start, mask=mask))


def test_untrained_residual_adversary_returns_the_white_balanced_image():
    lens = _start_lens()
    net = build_adversary(8, lens)
    sensor = torch.rand(2, 3, 37, 53) * 0.7
    torch.testing.assert_close(net(sensor), sensor / lens.gain().view(1, 3, 1, 1))
    torch.testing.assert_close(net(sensor).clamp(0, 1), white_balanced(sensor, lens))


def test_skips_and_residual_add_no_weights():
    plain, strong = RED10(8), RED10(8, skips=True, residual=True)
    assert set(strong.state_dict()) - set(plain.state_dict()) == {"input_gain"}
    assert sum(p.numel() for p in plain.parameters()) == sum(p.numel() for p in strong.parameters())


def test_skips_reach_the_output_at_full_resolution():
    # Changing one input pixel changes that output pixel far more with skips than through the /16 bottleneck.
    torch.manual_seed(0)
    net = RED10(8, skips=True)
    torch.manual_seed(0)
    plain = RED10(8)
    x = torch.rand(1, 3, 32, 32, requires_grad=True)
    (g_skip,) = torch.autograd.grad(net(x)[0, 0, 16, 16], x)
    (g_plain,) = torch.autograd.grad(plain(x)[0, 0, 16, 16], x)
    assert float(g_skip[0, :, 16, 16].abs().sum()) > 10 * float(g_plain[0, :, 16, 16].abs().sum())


@pytest.mark.slow
def test_pretraining_beats_the_white_balanced_image_by_the_margin_on_smoke(tmp_path, monkeypatch):
    profile = PROFILES["smoke"]
    lens = _start_lens()
    sampler = CropSampler.from_split("synthetic", profile.n_train, profile.image_size, profile.train_crop,
                                     profile.batch_size, 0)
    net, record = pretrain_adversary(lens, sampler, profile, 0, "cpu", tmp_path, "synthetic", progress=False)
    assert record["reached"] and record["margin_db"] == MARGIN_DB
    first, last = record["curve"][0], record["curve"][-1]
    assert first["adversary_psnr_db"] == pytest.approx(first["white_balanced_psnr_db"], abs=1e-6)
    assert last["adversary_psnr_db"] >= last["white_balanced_psnr_db"] + MARGIN_DB
    # Measured again, independently of the loop: the returned network is the one that beat it.
    again = Probe(sampler, 0, "cpu").measure(lens, net)
    assert again["adversary_psnr_db"] == pytest.approx(last["adversary_psnr_db"], abs=1e-9)
    # A second call is a cache hit with the same weights.
    monkeypatch.setattr(torch.optim.Adam, "step", lambda *a, **k: pytest.fail("trained again despite the cache"))
    cached, cached_record = pretrain_adversary(lens, sampler, profile, 0, "cpu", tmp_path, "synthetic", progress=False)
    assert cached_record == record
    for k, v in net.state_dict().items():
        assert torch.equal(cached.state_dict()[k], v), k
