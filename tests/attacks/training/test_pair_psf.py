"""The PSF and gain a known-pairs attacker measures from its pairs (attacks/training/pair_psf.py)."""

from __future__ import annotations

import pytest
import torch

from attacks.backends.real_fft import OtfCache
from attacks.backends.wiener import bayer_noise_sigma, wiener_deconvolve
from attacks.training.pair_psf import estimate_psf
from benchmark.runner.sensing import to_tensor
from benchmark.scenes.loading import load_scenes
from lenses.builtin import SPEC_DIR
from lenses.lens import Lens
from lenses.spec import load_spec


def _psnr(a: torch.Tensor, b: torch.Tensor) -> float:
    return float(-10 * torch.log10((a.clamp(0, 1) - b).pow(2).mean()))


@pytest.fixture(scope="module")
def defocus_pairs():
    lens = Lens(load_spec(SPEC_DIR / "defocus.toml"))
    sharp = to_tensor(load_scenes("synthetic", "train", 8, (256, 512), 0))
    with torch.no_grad():
        sensor = torch.cat([lens(sharp[i:i + 1], generator=torch.Generator().manual_seed(i)) for i in range(8)])
    return lens, sensor, sharp


def test_the_measured_psf_and_gain_are_the_lens_s(defocus_pairs):
    lens, sensor, sharp = defocus_pairs
    k = lens.psf().shape[-1]
    psf, gain = estimate_psf(sensor, sharp, 63)
    assert psf.shape == (3, 63, 63) and torch.allclose(psf.sum(dim=(1, 2)), torch.ones(3))
    assert torch.allclose(gain, lens.gain(), rtol=0.05)
    o = (63 - k) // 2
    inside = psf[:, o:o + k, o:o + k]
    assert float(psf.sum() - inside.sum()) < 0.05 * 3  # almost nothing outside the lens's support
    assert ((inside - lens.psf()).abs().sum(dim=(1, 2)) < 0.25).all()  # measured 0.12-0.17


def test_wiener_with_the_measured_psf_restores_as_with_the_true_one(defocus_pairs):
    lens, sensor, sharp = defocus_pairs
    psf, gain = estimate_psf(sensor[:6], sharp[:6], 63)
    test_sensor, test_sharp = sensor[6:], sharp[6:]

    def restored(p: torch.Tensor, g: torch.Tensor) -> float:
        out = wiener_deconvolve(test_sensor, OtfCache(p), sigma=bayer_noise_sigma(test_sensor)) / g.view(1, 3, 1, 1)
        return _psnr(out, test_sharp)

    true, measured = restored(lens.psf().detach(), lens.gain()), restored(psf, gain)
    assert measured > true - 0.5, (measured, true)
    assert measured > _psnr(test_sensor / lens.gain().view(1, 3, 1, 1), test_sharp) + 1.0


def test_bad_pairs_are_refused():
    x = torch.rand(2, 3, 32, 32)
    with pytest.raises(ValueError, match="aligned"):
        estimate_psf(x, x[:, :, :16], 9)
    with pytest.raises(ValueError, match="odd"):
        estimate_psf(x, x, 10)
