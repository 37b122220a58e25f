"""Fixtures for attacker tests: a fake lens (no dependency on ``lenses``) and a real photo."""

from __future__ import annotations

from types import SimpleNamespace

import numpy as np
import pytest
import torch
from skimage import data


def gaussian_psf(sigma_px: float, radius_px: int, dtype: torch.dtype = torch.float32) -> torch.Tensor:
    """Isotropic Gaussian PSF, shape (3, 2r+1, 2r+1), each channel summing to 1."""
    a = torch.arange(-radius_px, radius_px + 1, dtype=torch.float64)
    g = torch.exp(-(a[:, None] ** 2 + a[None, :] ** 2) / (2.0 * sigma_px**2))
    return (g / g.sum()).to(dtype).expand(3, -1, -1).clone()


class FakeLens:
    """Duck-typed ``attacks.LensLike``: Gaussian PSF and a configurable per-channel gain."""

    def __init__(self, sigma_px: float = 1.5, radius_px: int = 5, gain: tuple[float, ...] = (1.0, 1.0, 1.0)):
        self.spec = SimpleNamespace(name="fake-gaussian", sigma_px=sigma_px)
        self._psf = gaussian_psf(sigma_px, radius_px)
        self._gain = torch.tensor(gain)

    def psf(self) -> torch.Tensor:
        return self._psf.clone()

    def gain(self) -> torch.Tensor:
        return self._gain.clone()


@pytest.fixture
def fake_lens() -> FakeLens:
    return FakeLens()


@pytest.fixture
def make_fake_lens():
    return FakeLens


@pytest.fixture(scope="session")
def astronaut() -> torch.Tensor:
    """skimage's astronaut photo, shape (1, 3, 512, 512), float64 in [0, 1]."""
    return torch.from_numpy(data.astronaut().astype(np.float64) / 255.0).permute(2, 0, 1)[None]


@pytest.fixture
def make_gaussian_psf():
    return gaussian_psf
