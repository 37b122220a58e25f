import numpy as np
import pytest
import skimage.data
import skimage.metrics
import torch

from benchmark.results.metrics import psnr, ssim


@pytest.fixture(scope="module")
def pair():
    rng = np.random.default_rng(0)
    ref = skimage.data.astronaut()[::4, ::4].astype(np.float64) / 255
    noisy = np.clip(ref + rng.normal(0, 0.05, ref.shape), 0, 1)
    return ref, noisy


def t(img):
    return torch.from_numpy(img).permute(2, 0, 1)[None]


def test_psnr_matches_scikit_image(pair):
    ref, noisy = pair
    expected = skimage.metrics.peak_signal_noise_ratio(ref, noisy, data_range=1.0)
    assert float(psnr(t(noisy), t(ref))[0]) == pytest.approx(expected, rel=1e-9)


def test_ssim_matches_scikit_image(pair):
    ref, noisy = pair
    expected = skimage.metrics.structural_similarity(ref, noisy, data_range=1.0, channel_axis=2,
                                                     gaussian_weights=True, sigma=1.5, use_sample_covariance=False)
    assert float(ssim(t(noisy), t(ref))[0]) == pytest.approx(expected, abs=1e-9)


def test_ssim_of_identical_images_is_one_and_batches_are_independent(pair):
    ref, noisy = pair
    batch = torch.cat([t(ref), t(noisy)])
    refs = torch.cat([t(ref), t(ref)])
    s = ssim(batch, refs)
    assert float(s[0]) == pytest.approx(1.0) and float(s[1]) < 0.9
    assert float(ssim(t(noisy), t(ref))[0]) == pytest.approx(float(s[1]))
