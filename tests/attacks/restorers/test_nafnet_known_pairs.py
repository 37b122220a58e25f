"""nafnet-known-pairs and the shared training loop: it learns, and a second fit loads from the cache."""

from __future__ import annotations

import torch

import attacks
from benchmark.store.cache import ArtifactCache
from attacks.networks import NAFNet
from attacks.training.restorer_training import negative_psnr, random_crops, train_restorer


def _pairs(sigma: float = 0.5):
    def pairs():
        g = torch.Generator().manual_seed(0)
        sharp = torch.rand(4, 3, 32, 32, generator=g)
        yield sharp * sigma, sharp

    return pairs


def test_negative_psnr_is_minus_psnr():
    target = torch.zeros(2, 3, 8, 8)
    output = torch.full_like(target, 0.1)  # MSE 0.01 -> 20 dB
    torch.testing.assert_close(negative_psnr(output, target), torch.tensor(-20.0), atol=1e-4, rtol=0)


def test_random_crops_are_aligned_with_even_offsets():
    images = torch.arange(2 * 1 * 10 * 12, dtype=torch.float32).reshape(2, 1, 10, 12)
    a, b = random_crops([images, images + 0.5], 16, 4, torch.Generator().manual_seed(0))
    assert a.shape == (16, 1, 4, 4)
    torch.testing.assert_close(b, a + 0.5)
    offsets = a[:, 0, 0, 0].long() % 120  # value = row * 12 + col within an image
    assert ((offsets // 12) % 2 == 0).all() and ((offsets % 12) % 2 == 0).all()


def test_training_learns_a_gain():
    torch.manual_seed(0)
    model = NAFNet(width=4, middle_blk_num=1, enc_blk_nums=(1,), dec_blk_nums=(1,))
    sharp = torch.rand(4, 3, 16, 16, generator=torch.Generator().manual_seed(0))
    losses = train_restorer(model, lambda g: (sharp * 0.5, sharp), steps=40, device="cpu", seed=0)
    assert losses[-1] < losses[0] - 2.0, f"PSNR only went from {-losses[0]:.1f} to {-losses[-1]:.1f} dB"


def test_second_fit_loads_from_cache(fake_lens, make_fake_lens, tmp_path):
    ctx = attacks.FitContext(lens=fake_lens, train_pairs=_pairs(), artifacts=ArtifactCache(tmp_path), seed=0)
    first = attacks.load("nafnet-known-pairs", backend="torch")
    first.fit(ctx)
    second = attacks.load("nafnet-known-pairs", backend="torch")
    second.fit(ctx)
    assert (first.trained, second.trained) == (True, False)
    files = list(tmp_path.rglob("*.safetensors"))
    assert len(files) == 1
    sensor = torch.rand(1, 3, 24, 24)
    torch.testing.assert_close(first.restore(sensor), second.restore(sensor), atol=0, rtol=0)
    # The key holds the lens: another lens, or another seed, trains its own model.
    other = attacks.load("nafnet-known-pairs", backend="torch")
    other.fit(attacks.FitContext(lens=make_fake_lens(sigma_px=3.0), train_pairs=_pairs(),
                                 artifacts=ArtifactCache(tmp_path), seed=0))
    reseeded = attacks.load("nafnet-known-pairs", backend="torch")
    reseeded.fit(attacks.FitContext(lens=fake_lens, train_pairs=_pairs(), artifacts=ArtifactCache(tmp_path), seed=1))
    assert other.trained and reseeded.trained
    assert len(list(tmp_path.rglob("*.safetensors"))) == 3


def test_truncated_cached_weights_are_reported_and_retrained(fake_lens, tmp_path, caplog):
    ctx = attacks.FitContext(lens=fake_lens, train_pairs=_pairs(), artifacts=ArtifactCache(tmp_path), seed=0)
    attacks.load("nafnet-known-pairs", backend="torch").fit(ctx)
    (weights,) = tmp_path.rglob("*.safetensors")
    good = weights.read_bytes()
    weights.write_bytes(good[: len(good) // 2])
    again = attacks.load("nafnet-known-pairs", backend="torch")
    with caplog.at_level("WARNING"):
        again.fit(ctx)
    assert again.trained is True  # rebuilt, not reused
    assert str(weights) in caplog.text and weights.read_bytes() == good  # same seed: the same weights again
