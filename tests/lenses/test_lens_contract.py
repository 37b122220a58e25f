"""One contract for every registered lens and every shipped spec: what attackers and the runner rely on.

PSF (3, K, K) with each channel summing to 1; sensor output (B, 3, H, W) in [0, 1]; gradients reach
the trainable Zernike coefficients. Co-designed lenses are trained on the smoke profile (seconds).
"""

from pathlib import Path

import pytest
import torch

import lenses
from benchmark.store.profiles import get_profile

SPECS = sorted((Path(lenses.__file__).parent / "specs").rglob("*.toml"))  # the examples/ too
REGISTERED = sorted(lenses.available())


@pytest.fixture(scope="module")
def cache(tmp_path_factory):
    return tmp_path_factory.mktemp("lens-cache")


def check_contract(lens: lenses.Lens) -> None:
    psf = lens.psf()
    k = psf.shape[-1]
    assert psf.shape == (3, k, k) and k % 2 == 1
    assert torch.allclose(psf.sum(dim=(1, 2)), torch.ones(3, dtype=psf.dtype), atol=1e-5)
    assert bool((psf >= 0).all())
    x = torch.rand(2, 3, 48, 64, generator=torch.Generator().manual_seed(0))
    y = lens(x, generator=torch.Generator().manual_seed(1))
    assert y.shape == x.shape and bool(torch.isfinite(y).all())
    assert float(y.min()) >= 0.0 and float(y.max()) <= 1.0
    if lens.coefficients_um.requires_grad:
        lens.zero_grad()
        # A smooth loss of the image through the whole camera (noise, clipping, quantisation).
        (lens(x, generator=torch.Generator().manual_seed(1)) * torch.linspace(0, 1, 64)).sum().backward()
        grad = lens.coefficients_um.grad
        assert grad is not None and bool(torch.isfinite(grad).all()) and float(grad.abs().sum()) > 0


@pytest.mark.parametrize("spec", SPECS, ids=lambda p: p.name)
def test_every_spec_file_keeps_the_contract(spec):
    check_contract(lenses.load(spec))


@pytest.mark.slow
@pytest.mark.parametrize("name", REGISTERED)
def test_every_registered_lens_keeps_the_contract(name, cache):
    check_contract(lenses.load(name, profile=get_profile("smoke"), seed=0, device="cpu", cache_dir=cache))
