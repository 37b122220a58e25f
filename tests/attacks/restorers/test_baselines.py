"""`identity` (white-balanced by the sensor's gain) and the `raw` reference row."""

from __future__ import annotations

import pytest
import torch

import attacks
import lenses


def test_identity_divides_by_the_known_gain(make_fake_lens):
    gain = (0.5, 0.8, 0.25)
    identity = attacks.load("identity")
    identity.fit(attacks.FitContext(lens=make_fake_lens(gain=gain)))
    sensor = torch.rand(2, 3, 8, 10, generator=torch.Generator().manual_seed(0)) * 0.25
    expected = (sensor / torch.tensor(gain)[:, None, None]).clamp(0, 1)
    assert torch.allclose(identity.restore(sensor), expected)
    with pytest.raises(attacks.MissingRequirementError, match="lens"):
        attacks.load("identity").fit(attacks.FitContext())


def test_identity_makes_grey_grey_through_the_real_sensor():
    lens = lenses.load("sensor-only")
    grey = torch.full((1, 3, 64, 64), 0.5)
    sensor = lens(grey, generator=torch.Generator().manual_seed(1))
    raw_means = sensor.mean(dim=(0, 2, 3))
    assert float(raw_means.max() - raw_means.min()) > 0.1  # the tint is there
    identity = attacks.load("identity")
    identity.fit(attacks.FitContext(lens=lens))
    balanced = identity.restore(sensor).mean(dim=(0, 2, 3))
    assert torch.allclose(balanced, torch.full((3,), 0.5), atol=0.005), balanced


def test_raw_is_a_reference_and_returns_the_sensor_image():
    raw = attacks.load("raw")
    assert raw.reference and not attacks.load("identity").reference
    assert not any(attacks.load(n).reference for n in ("wiener-known-psf", "gray-world", "demosaic-vng"))
    sensor = torch.rand(1, 3, 6, 6)
    out = raw.restore(sensor)
    assert torch.equal(out, sensor) and out.data_ptr() != sensor.data_ptr()
