"""`demosaic-vng`: mosaic recovery, OpenCV's Bayer naming, and a better demosaic than bilinear."""

from __future__ import annotations

import pytest
import torch

import attacks
import lenses
from attacks.restorers.demosaic_vng import demosaic_opencv, recover_mosaic
from lenses.sensor import demosaic_bilinear, mosaic


def _psnr(x: torch.Tensor, ref: torch.Tensor) -> float:
    return float(10 * torch.log10(1.0 / ((x.double() - ref.double()) ** 2).mean()))


def test_bilinear_demosaic_keeps_the_samples_so_the_mosaic_comes_back_exactly():
    lens = lenses.load("sensor-only")
    sensor_model = lens.sensor
    scene = torch.rand(2, 3, 30, 44, generator=torch.Generator().manual_seed(0))
    sensor = lens(scene, generator=torch.Generator().manual_seed(3))
    electrons = sensor_model.raw_electrons(scene, generator=torch.Generator().manual_seed(3))
    counts = torch.round(electrons * (sensor_model.levels / sensor_model.spec.full_well_e))
    assert torch.equal(recover_mosaic(sensor), counts.double())


@pytest.mark.parametrize("method", ["vng", "ea"])
def test_opencv_pattern_and_channel_order(method):
    # A flat colour is rebuilt exactly by any demosaic with the right pattern; a wrong Bayer
    # code or BGR order swaps or mixes the channels.
    colour = torch.tensor([0.8, 0.4, 0.1])
    rgb = colour[None, :, None, None].expand(1, 3, 16, 20)
    counts = torch.round(mosaic(rgb) * 1023)
    out = demosaic_opencv(counts, 10, method)
    assert out.shape == (1, 3, 16, 20)
    interior = out[0, :, 3:-3, 3:-3].reshape(3, -1)
    assert torch.allclose(interior, colour[:, None], atol=1.0 / 255), interior.mean(1)


def test_vng_beats_bilinear_on_a_photo(astronaut):
    # Noise-free mosaic of a photo: what the demosaic alone loses.
    scene = astronaut.float()[..., :256, :256]
    counts = torch.round(mosaic(scene) * 1023)
    bilinear = _psnr(demosaic_bilinear(counts / 1023), scene)
    vng = _psnr(demosaic_opencv(counts, 10, "vng"), scene)
    assert vng > bilinear + 1.0, (bilinear, vng)


def test_restorer_divides_by_the_gain_and_improves_on_identity(astronaut, make_fake_lens):
    lens = lenses.load("sensor-only")
    scene = astronaut.float()[..., :128, :128]
    sensor = lens(scene, generator=torch.Generator().manual_seed(0))
    ctx = attacks.FitContext(lens=lens)
    vng, identity = attacks.load("demosaic-vng"), attacks.load("identity")
    vng.fit(ctx)
    identity.fit(ctx)
    assert _psnr(vng.restore(sensor), scene) > _psnr(identity.restore(sensor), scene) + 0.5
    with pytest.raises(ValueError, match="method"):
        attacks.load("demosaic-vng", method="ahd")
