"""Gray-world white balance: equal channel means, brightness kept, tint removed."""

from __future__ import annotations

import torch

from attacks.restorers.gray_world import GrayWorld, gray_world_balance


def test_channel_means_become_the_image_mean(astronaut):
    x = astronaut.float() * 0.5  # dark enough that no balanced value clips
    balanced = gray_world_balance(x)
    means = balanced.mean(dim=(-2, -1))
    torch.testing.assert_close(means, means.mean(dim=1, keepdim=True).expand_as(means), atol=1e-5, rtol=0)
    torch.testing.assert_close(balanced.mean(), x.mean(), atol=1e-5, rtol=0)


def test_a_channel_tint_is_undone_up_to_brightness(astronaut):
    x = astronaut.float() * 0.4
    tint = torch.tensor([0.45, 0.60, 0.50])[:, None, None]
    means = x.mean(dim=(-2, -1))[0]
    # Tinting scales channel c by t_c; gray world then differs only by the change in mean intensity.
    brightness = (tint.flatten() * means).mean() / means.mean()
    torch.testing.assert_close(gray_world_balance(tint * x), brightness * gray_world_balance(x), atol=1e-5, rtol=0)


def test_per_image_and_clamped():
    x = torch.rand(2, 3, 16, 16, generator=torch.Generator().manual_seed(0))
    x[1, 0] *= 0.05  # nearly empty red channel: a large gain that must clamp at 1
    balanced = GrayWorld().restore(x)
    assert balanced.min() >= 0 and balanced.max() <= 1
    torch.testing.assert_close(balanced[:1], gray_world_balance(x[:1]))
