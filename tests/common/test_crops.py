"""The one crop sampler: aligned crops, even offsets, flips, and errors that name the mismatch."""

import pytest
import torch

from common.crops import random_crops


def test_crops_are_aligned_and_at_even_offsets():
    h, w = 20, 30
    # Each pixel holds its own coordinates, so a crop reveals where it was cut.
    ys, xs = torch.meshgrid(torch.arange(h), torch.arange(w), indexing="ij")
    images = torch.stack([torch.stack([ys, xs, ys + xs]).float() + 1000 * i for i in range(5)])
    labels = (ys * w + xs).expand(5, h, w) + 1000 * torch.arange(5)[:, None, None]
    crops, crop_labels = random_crops([images, labels], (8, 10), torch.Generator().manual_seed(0), n=32)
    assert crops.shape == (32, 3, 8, 10) and crop_labels.shape == (32, 8, 10)
    image_index = (crops[:, 0, 0, 0] // 1000).long()
    y0 = crops[:, 0, 0, 0] - 1000 * image_index
    x0 = crops[:, 1, 0, 0] - 1000 * image_index
    assert bool((y0 % 2 == 0).all()) and bool((x0 % 2 == 0).all())
    assert bool((y0 <= h - 8).all()) and bool((x0 <= w - 10).all())
    expected_labels = (y0 * w + x0).long() + 1000 * image_index
    assert torch.equal(crop_labels[:, 0, 0], expected_labels)  # labels cut at the same place
    assert len(set(image_index.tolist())) > 1


def test_one_crop_per_image_in_order_and_reproducible():
    images = torch.arange(4.0)[:, None, None, None].expand(4, 3, 16, 16)
    a = random_crops([images], (8, 8), torch.Generator().manual_seed(3))[0]
    b = random_crops([images], (8, 8), torch.Generator().manual_seed(3))[0]
    assert torch.equal(a, b) and a[:, 0, 0, 0].tolist() == [0.0, 1.0, 2.0, 3.0]


def test_flips_mirror_some_crops_left_right():
    row = torch.arange(16.0).expand(1, 1, 4, 16)
    crops = random_crops([row.expand(64, 1, 4, 16)], (4, 16), torch.Generator().manual_seed(0), hflip=True)[0]
    flipped = crops[:, 0, 0, 0] == 15
    assert 0 < int(flipped.sum()) < 64 and torch.equal(crops[flipped][:, 0, 0], row[0, 0, 0].flip(0).expand(
        int(flipped.sum()), 16))


def test_mismatched_or_too_large_inputs_are_named():
    with pytest.raises(ValueError, match="not aligned"):
        random_crops([torch.zeros(2, 3, 8, 8), torch.zeros(2, 8, 9)], (4, 4), torch.Generator())
    with pytest.raises(ValueError, match=r"crop \(9, 4\) does not fit"):
        random_crops([torch.zeros(2, 3, 8, 8)], (9, 4), torch.Generator())
