import numpy as np
import pytest
import scipy.ndimage
import torch

from lenses.convolve import convolve, convolve_direct, convolve_fft


@pytest.mark.parametrize("k", [3, 9, 31])
def test_fft_and_direct_agree_and_match_scipy(k):
    g = torch.Generator().manual_seed(k)
    x = torch.rand(2, 3, 40, 57, generator=g, dtype=torch.float64)
    psf = torch.rand(3, k, k, generator=g, dtype=torch.float64)
    psf = psf / psf.sum(dim=(1, 2), keepdim=True)
    direct, fft = convolve_direct(x, psf), convolve_fft(x, psf)
    torch.testing.assert_close(direct, fft, atol=1e-10, rtol=0)
    # scipy's 'mirror' boundary is torch's 'reflect' (the edge pixel is not repeated).
    ref = np.stack([scipy.ndimage.convolve(x[1, c].numpy(), psf[c].numpy(), mode="mirror") for c in range(3)])
    np.testing.assert_allclose(fft[1].numpy(), ref, atol=1e-10)


def test_delta_psf_is_identity_and_shape_is_checked():
    x = torch.rand(1, 3, 20, 30)
    delta = torch.zeros(3, 5, 5)
    delta[:, 2, 2] = 1
    torch.testing.assert_close(convolve(x, delta), x)
    with pytest.raises(ValueError, match="odd K"):
        convolve(x, torch.ones(3, 4, 4))


def test_psf_larger_than_image_still_convolves():
    x = torch.rand(1, 3, 6, 9, dtype=torch.float64)
    psf = torch.ones(3, 15, 15, dtype=torch.float64) / 225
    torch.testing.assert_close(convolve_direct(x, psf), convolve_fft(x, psf), atol=1e-12, rtol=0)


def test_apply_otf_without_autograd_equals_the_differentiable_path():
    """The no-grad path (one image at a time, spectrum multiplied in place) computes the same
    convolution as the batched differentiable one."""
    from lenses.convolve import apply_otf, fft_shape, psf_otf
    g = torch.Generator().manual_seed(3)
    x = torch.rand(3, 3, 50, 70, generator=g)
    psf = torch.rand(3, 21, 21, generator=g)
    otf = psf_otf(psf / psf.sum(dim=(1, 2), keepdim=True), fft_shape(50, 70, 21))
    with torch.no_grad():
        fast = apply_otf(x, otf, 21)
    slow = apply_otf(x.clone().requires_grad_(True), otf, 21)
    assert slow.requires_grad and not fast.requires_grad
    torch.testing.assert_close(fast, slow.detach(), atol=1e-6, rtol=0)
