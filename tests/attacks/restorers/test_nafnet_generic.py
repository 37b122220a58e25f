"""nafnet-generic: generic degradations, one model for every lens, and official checkpoints."""

from __future__ import annotations

import math

import pytest
import torch

import attacks
from benchmark.store.cache import ArtifactCache
from attacks.training.degradations import degrade, disk_kernel, gaussian_kernel, motion_kernel, random_kernels
from attacks.restorers.gray_world import gray_world_balance
from attacks.networks import NAFNet


def _pairs():
    g = torch.Generator().manual_seed(0)
    sharp = torch.rand(4, 3, 32, 32, generator=g)
    yield sharp * 0.5, sharp


@pytest.mark.parametrize("kernel", [gaussian_kernel(2.0), disk_kernel(5.0), motion_kernel(9.0, 0.7)],
                         ids=["gaussian", "disk", "motion"])
def test_kernels_are_normalised_and_centred(kernel):
    assert math.isclose(float(kernel.sum()), 1.0, rel_tol=1e-5)
    a = torch.arange(kernel.shape[-1], dtype=torch.float32) - kernel.shape[-1] // 2
    centroid = (float((kernel.sum(0) * a).sum()), float((kernel.sum(1) * a).sum()))
    assert max(map(abs, centroid)) < 1e-3


def test_disk_kernel_has_the_area_of_its_radius():
    k = disk_kernel(6.0)
    support = float((k > 0.5 * k.max()).sum())
    assert abs(support - math.pi * 36) < 0.05 * math.pi * 36


def test_random_kernels_include_identity_and_blur():
    kernels = random_kernels(64, torch.Generator().manual_seed(0))
    peaks = kernels.flatten(1).max(dim=1).values
    assert (peaks == 1).any() and (peaks < 0.5).any()


def test_degrade_keeps_range_and_shape():
    sharp = torch.rand(4, 3, 32, 32)
    out = degrade(sharp, torch.Generator().manual_seed(0))
    assert out.shape == sharp.shape and out.min() >= 0 and out.max() <= 1


def test_one_model_for_every_lens(fake_lens, make_fake_lens, tmp_path):
    first = attacks.load("nafnet-generic", backend="torch")
    first.fit(attacks.FitContext(lens=fake_lens, train_pairs=_pairs, artifacts=ArtifactCache(tmp_path), seed=0))
    second = attacks.load("nafnet-generic", backend="torch")
    second.fit(attacks.FitContext(lens=make_fake_lens(sigma_px=4.0), train_pairs=_pairs,
                                  artifacts=ArtifactCache(tmp_path), seed=0))
    assert (first.trained, second.trained) == (True, False)
    assert len(list(tmp_path.rglob("*.safetensors"))) == 1


def test_official_checkpoint_layout_is_used(tmp_path):
    arch = {"width": 4, "middle_blk_num": 1, "enc_blk_nums": (1, 2), "dec_blk_nums": (1, 1)}
    torch.manual_seed(0)
    reference = NAFNet(**arch).eval()
    with torch.no_grad():
        for name, p in reference.named_parameters():
            if name.endswith(("beta", "gamma")):
                p.normal_(0, 0.5)
    path = tmp_path / "NAFNet-GoPro-width4.pth"
    torch.save({"params": reference.state_dict()}, path)  # the official release's wrapper

    attack = attacks.load("nafnet-generic", checkpoint=str(path), checkpoint_arch=arch, backend="torch")
    attack.fit(attacks.FitContext(cache_dir=tmp_path / "cache"))  # no train_pairs: nothing to train
    assert attack.trained is False and not (tmp_path / "cache").exists()
    sensor = torch.rand(1, 3, 24, 40)
    with torch.no_grad():
        expected = reference(gray_world_balance(sensor)).clamp(0, 1)
    torch.testing.assert_close(attack.restore(sensor), expected, atol=1e-6, rtol=0)
    assert len(attack.describe()["checkpoint_sha256"]) == 64


def test_missing_checkpoint_is_an_error(tmp_path):
    with pytest.raises(FileNotFoundError, match="nope.pth"):
        attacks.load("nafnet-generic", checkpoint=str(tmp_path / "nope.pth"))
