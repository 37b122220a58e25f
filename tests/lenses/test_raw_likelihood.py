"""The raw-electron forward model of the ideal observer: against scipy's direct convolution, and the box blur
(cut PSF, wrapped transform) against the whole linear convolution it replaces."""

from __future__ import annotations

import numpy as np
import pytest
import torch
from scipy.signal import convolve2d

from lenses.raw_likelihood import BoxBlur, raw_mean_electrons
from lenses.sensor import bayer_masks


def random_psf(k: int, seed: int) -> torch.Tensor:
    psf = torch.rand(3, k, k, generator=torch.Generator().manual_seed(seed), dtype=torch.float64)
    return psf / psf.sum((-2, -1), keepdim=True)


def test_raw_mean_electrons_is_scipys_full_convolution_at_each_site():
    rng = np.random.default_rng(0)
    patch = torch.from_numpy(rng.random((2, 3, 9, 14)))
    psf, gain = random_psf(7, 1), torch.tensor([900.0, 1200.0, 700.0], dtype=torch.float64)
    surround = 0.25
    got = raw_mean_electrons(patch, surround, psf, gain, (1, 0))
    for n in range(2):
        # The surround is an infinite plane of `surround`: pad it by the PSF's full size, convolve, cut.
        k = psf.shape[-1]
        want = np.stack([convolve2d(np.pad(patch[n, c].numpy(), k - 1, constant_values=surround), psf[c].numpy(),
                                    mode="valid") for c in range(3)])
        want = want * gain.numpy()[:, None, None]
        masks = bayer_masks(want.shape[1] + 1, want.shape[2] + 1, dtype=torch.float64)[:, 1:, :-1].numpy()
        np.testing.assert_allclose(got[n].numpy(), (want * masks).sum(0), rtol=1e-10, atol=1e-9)


@pytest.mark.parametrize("size_hw, k, phase", [((10, 48), 87, (0, 1)), ((17, 80), 87, (1, 0)), ((30, 40), 21, (1, 1)),
                                               ((3, 5), 9, (0, 0))])
def test_box_blur_is_the_linear_convolution_on_the_box(size_hw, k, phase):
    """Boxes narrower and wider than the PSF, every Bayer phase: the cut, wrapped transform changes nothing."""
    h, w = size_hw
    rng = np.random.default_rng(h * w)
    patch = torch.from_numpy(rng.random((4, 3, h, w)))
    psf, gain = random_psf(k, k), torch.tensor([800.0, 1000.0, 600.0], dtype=torch.float64)
    r = k // 2
    whole = raw_mean_electrons(patch, 0.0, psf, gain, (phase[0] - r, phase[1] - r))[:, r:r + h, r:r + w]
    got = BoxBlur(psf, gain, (h, w), phase)(patch)
    assert got.shape == (4, h, w)
    torch.testing.assert_close(got, whole, rtol=1e-10, atol=1e-9)
    if k > 2 * h - 1:  # the PSF's rows beyond the box's reach are cut: changing them changes nothing
        far = psf.clone()
        far[:, :r - h + 1] += 1.0
        torch.testing.assert_close(BoxBlur(far, gain, (h, w), phase)(patch), got, rtol=1e-10, atol=1e-9)


def test_box_blur_names_a_patch_of_the_wrong_size():
    blur = BoxBlur(random_psf(5, 0), torch.ones(3, dtype=torch.float64), (6, 10))
    with pytest.raises(ValueError, match=r"\(N, 3, 6, 10\)"):
        blur(torch.zeros(1, 3, 6, 11, dtype=torch.float64))
