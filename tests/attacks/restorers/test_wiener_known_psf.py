"""Wiener deconvolution with a known PSF: a reference implementation, exact inversion, gain."""

from __future__ import annotations

import numpy as np
import pytest
import torch
from scipy import ndimage
from skimage.restoration import wiener as skimage_wiener

import attacks
from attacks.backends.wiener import estimate_noise_sigma, wiener_deconvolve


def blur(x: torch.Tensor, psf: torch.Tensor, mode: str = "mirror") -> torch.Tensor:
    """Per-channel true convolution by scipy (an implementation independent of ours)."""
    out = [ndimage.convolve(x[0, c].numpy(), psf[c].double().numpy(), mode=mode) for c in range(3)]
    return torch.from_numpy(np.stack(out))[None]


def psnr_db(estimate: torch.Tensor, truth: torch.Tensor) -> float:
    return float(10 * torch.log10(1.0 / (estimate.clamp(0, 1) - truth).square().mean()))


def test_beats_identity_on_blurred_noisy_photo(astronaut, make_gaussian_psf, make_fake_lens):
    # Measured: identity 24.85 dB, Wiener 27.7 dB (sigma 2 px, noise 0.01); margin asserted 2 dB.
    torch.manual_seed(0)
    psf = make_gaussian_psf(2.0, 7)
    x = astronaut.float()
    sensor = (blur(astronaut, psf).float() + 0.01 * torch.randn_like(x)).clamp(0, 1)
    lens = make_fake_lens(sigma_px=2.0, radius_px=7)
    wiener = attacks.load("wiener-known-psf")
    wiener.fit(attacks.FitContext(lens=lens))
    identity = attacks.load("identity")
    identity.fit(attacks.FitContext(lens=lens))
    assert psnr_db(wiener.restore(sensor), x) > psnr_db(identity.restore(sensor), x) + 2.0


def test_matches_skimage_wiener_in_the_interior(astronaut, make_gaussian_psf):
    psf = make_gaussian_psf(1.5, 5, torch.float64)
    x = astronaut[..., 128:384, 128:384]
    y = blur(x, psf)
    balance = 0.01
    ours = wiener_deconvolve(y, psf, balance=balance)
    # reg = a unit impulse makes skimage's regularizer the identity, i.e. a constant NSR.
    ref = np.stack([
        skimage_wiener(y[0, c].numpy(), psf[c].numpy(), balance, reg=np.ones((1, 1)), clip=False)
        for c in range(3)
    ])
    border = 24  # skimage filters circularly; compare where the wrap-around has decayed
    diff = (ours[0].numpy() - ref)[:, border:-border, border:-border]
    assert np.abs(diff).max() < 2e-3


def test_exact_inverse_of_a_circular_blur():
    # Asymmetric PSF so a flipped or off-centre OTF would fail; |OTF| >= 0.6 - 0.4 > 0.
    psf = torch.zeros(3, 3, 3, dtype=torch.float64)
    psf[:, 1, 1], psf[:, 1, 2], psf[:, 2, 1] = 0.6, 0.25, 0.15
    x = torch.rand(2, 3, 40, 52, dtype=torch.float64, generator=torch.Generator().manual_seed(1))
    y = torch.stack([blur(x[i : i + 1], psf, mode="wrap")[0] for i in range(2)])
    restored = wiener_deconvolve(y, psf, balance=0.0, pad=False)
    torch.testing.assert_close(restored, x, atol=1e-10, rtol=0)


def test_noise_sigma_estimate_on_a_smooth_photo(astronaut, make_gaussian_psf):
    torch.manual_seed(0)
    smooth = blur(astronaut, make_gaussian_psf(2.0, 7, torch.float64))
    for sigma in (0.003, 0.01, 0.03):
        estimate = estimate_noise_sigma(smooth + sigma * torch.randn_like(smooth)) / sigma
        # Leftover image detail in the finest Haar band can only add: measured +13 % at 0.003.
        assert ((estimate > 0.97) & (estimate < 1.15)).all(), estimate


def test_gain_is_divided_out(astronaut, make_gaussian_psf, make_fake_lens):
    torch.manual_seed(0)
    gain = (0.45, 0.60, 0.50)
    x = astronaut[..., :128, :128].float()
    blurred = blur(astronaut[..., :128, :128], make_gaussian_psf(1.5, 5)).float()
    noise = 0.005 * torch.randn_like(x)
    tint = torch.tensor(gain)[:, None, None]
    plain, tinted = attacks.load("wiener-known-psf"), attacks.load("wiener-known-psf")
    plain.fit(attacks.FitContext(lens=make_fake_lens()))
    tinted.fit(attacks.FitContext(lens=make_fake_lens(gain=gain)))
    # The NSR is scale-invariant, so a tinted, equally noisy (relative) sensor restores the same.
    torch.testing.assert_close(
        tinted.restore(tint * (blurred + noise)), plain.restore(blurred + noise), atol=1e-4, rtol=0
    )


def test_batch_items_are_independent(fake_lens):
    sensor = torch.rand(3, 3, 48, 40, generator=torch.Generator().manual_seed(2))
    sensor[1] *= 0.3
    wiener = attacks.load("wiener-known-psf")
    wiener.fit(attacks.FitContext(lens=fake_lens))
    batched = wiener.restore(sensor)
    single = torch.cat([wiener.restore(sensor[i : i + 1]) for i in range(3)])
    torch.testing.assert_close(batched, single, atol=1e-5, rtol=0)


def test_restore_before_fit_and_fit_without_lens_fail_clearly():
    wiener = attacks.load("wiener-known-psf")
    with pytest.raises(RuntimeError, match="fit"):
        wiener.restore(torch.zeros(1, 3, 8, 8))
    with pytest.raises(attacks.MissingRequirementError, match=r"wiener-known-psf.*lens"):
        wiener.fit(attacks.FitContext())


@pytest.mark.skipif(not torch.cuda.is_available(), reason="needs CUDA")
def test_cuda_matches_cpu(fake_lens):
    sensor = torch.rand(2, 3, 64, 64, generator=torch.Generator().manual_seed(3))
    wiener = attacks.load("wiener-known-psf")
    wiener.fit(attacks.FitContext(lens=fake_lens, device="cuda"))
    on_gpu = wiener.restore(sensor.cuda())
    assert on_gpu.device.type == "cuda"
    torch.testing.assert_close(on_gpu.cpu(), wiener.restore(sensor), atol=1e-4, rtol=0)
