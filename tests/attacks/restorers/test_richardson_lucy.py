"""richardson-lucy-known-psf: equals scikit-image's Richardson-Lucy, and deblurs."""

from __future__ import annotations

import numpy as np
import pytest
import torch
from skimage.restoration import richardson_lucy as skimage_richardson_lucy

import attacks
from attacks.restorers.richardson_lucy_known_psf import ITERATION_LADDER, richardson_lucy, richardson_lucy_iterates
from lenses.convolve import convolve


def _psnr(x: torch.Tensor, ref: torch.Tensor) -> float:
    return float(10 * torch.log10(1 / (x - ref).pow(2).mean()))


def test_matches_skimage_in_the_interior(astronaut, make_gaussian_psf):
    iterations, radius = 10, 3
    psf = make_gaussian_psf(1.2, radius, torch.float64)
    scene = astronaut[..., 200:328, 200:328]
    blurred = convolve(scene, psf)
    ours = richardson_lucy(blurred, psf, iterations)
    reference = np.stack([
        skimage_richardson_lucy(blurred[0, c].numpy(), psf[c].numpy(), num_iter=iterations, clip=False)
        for c in range(3)
    ])
    # skimage zero-pads, we reflect-pad: each iteration carries the border difference one PSF
    # radius further in, so compare beyond iterations x radius from the edges.
    margin = iterations * radius
    inner = (slice(margin, -margin), slice(margin, -margin))
    np.testing.assert_allclose(ours[0][(slice(None), *inner)].numpy(), reference[(slice(None), *inner)],
                               atol=1e-6)


def test_iterations_are_chosen_on_train_pairs_and_beat_identity(astronaut, make_fake_lens):
    gain = (0.6, 0.9, 0.75)
    lens = make_fake_lens(sigma_px=2.0, radius_px=8, gain=gain)
    g = torch.Generator().manual_seed(0)

    def sense(scene: torch.Tensor) -> torch.Tensor:
        blurred = convolve(scene, lens.psf().double()) * torch.tensor(gain, dtype=torch.float64)[:, None, None]
        return (blurred + 0.003 * torch.randn(blurred.shape, generator=g, dtype=torch.float64)).clamp(0, 1)

    train_scene, test_scene = astronaut[..., :128, :256], astronaut[..., 300:428, 200:456]

    def pairs():
        yield sense(train_scene), train_scene

    attack = attacks.load("richardson-lucy-known-psf")
    attack.fit(attacks.FitContext(lens=lens, train_pairs=pairs))
    description = attack.describe()
    assert description["iterations"] in ITERATION_LADDER
    assert description["iterations"] == int(max(description["ladder_psnr_db"], key=description["ladder_psnr_db"].get))
    sensor = sense(test_scene)
    restored = attack.restore(sensor)
    # Identity is charitably gain-corrected so the margin measures deblurring, not colour.
    identity = (sensor / torch.tensor(gain, dtype=torch.float64)[:, None, None]).clamp(0, 1)
    gain_db = _psnr(restored, test_scene) - _psnr(identity, test_scene)
    assert gain_db > 1.5, f"Richardson-Lucy improves PSNR by only {gain_db:.2f} dB"


def test_fixed_iterations_skip_the_search(fake_lens):
    attack = attacks.load("richardson-lucy-known-psf", iterations=7)
    attack.fit(attacks.FitContext(lens=fake_lens))
    assert attack.describe()["iterations"] == 7 and attack.describe()["chosen_by"] == "fixed"
    with pytest.raises(ValueError, match="iterations"):
        attacks.load("richardson-lucy-known-psf", iterations=0)


def test_a_delta_psf_with_dark_regions_stays_finite_and_keeps_the_image():
    """sensor-only's 1 x 1 PSF: float32 FFT rounding over near-zero padding once blew up to inf by
    iteration 8 (a quick plate window came back all NaN); the estimate must stay the image."""
    g = torch.Generator().manual_seed(0)
    y = (torch.rand(1, 3, 64, 832, generator=g) * 1023).round() / 1023
    y[..., :, :40] = 0
    y[..., :, -40:] = 0
    y[..., :20, :] = 0
    y = y * (torch.rand(1, 3, 64, 832, generator=g) > 0.3)
    for _, estimate in richardson_lucy_iterates(y, torch.ones(3, 1, 1), 30):
        assert torch.isfinite(estimate).all()
    assert float((estimate - y).abs().max()) < 1e-4
