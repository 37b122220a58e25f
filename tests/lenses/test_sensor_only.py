"""The `sensor-only` reference lens: a delta PSF in front of the suite's sensor."""

from __future__ import annotations

import torch

import lenses


def test_sensor_only_psf_is_a_delta():
    lens = lenses.load("sensor-only")
    assert "sensor-only" in lenses.available()
    psf, energy = lens.psf_and_energy()
    k = psf.shape[-1]
    assert psf.shape == (3, k, k) and k % 2 == 1
    assert torch.allclose(psf.sum(dim=(1, 2)), torch.ones(3))
    assert torch.equal(psf[:, k // 2, k // 2], torch.ones(3))  # all energy in the centre pixel
    assert torch.equal(energy, torch.ones(3)) and lens.geometry.psf_size_px == k


def test_sensor_only_output_is_the_sensor_model_of_the_sharp_scene():
    lens = lenses.load("sensor-only")
    scene = torch.rand(2, 3, 24, 36, generator=torch.Generator().manual_seed(0))
    through_lens = lens(scene, generator=torch.Generator().manual_seed(4))
    sensor_alone = lens.sensor(scene, generator=torch.Generator().manual_seed(4))
    assert torch.equal(through_lens, sensor_alone)
    # The same sensor as every other lens: same tint, and the ideal lens does blur.
    ideal = lenses.load("ideal")
    assert torch.equal(lens.gain(), ideal.gain())
    assert not torch.equal(ideal(scene, generator=torch.Generator().manual_seed(4)), through_lens)
