"""The mIoU scene bootstrap sums each resample's scenes through a count matrix: the same sums, bit for bit,
as gathering the drawn scenes (the reference), without the (R, n, 2, C) array."""

import numpy as np
import pytest

from benchmark.results.pooled import _miou, _resampled_sums


@pytest.mark.parametrize("n, classes", [(1, 3), (7, 19), (64, 19)])
def test_resampled_sums_equal_the_gathered_scenes_bit_for_bit(n, classes):
    rng = np.random.default_rng(n)
    x = rng.integers(0, 500_000, size=(n, 2, classes)).astype(float)
    x[:, 1] += x[:, 0]  # a union holds its intersection
    draws = rng.integers(0, n, size=(257, n))
    assert np.array_equal(_resampled_sums(x, draws), x[draws].sum(axis=1))


def test_miou_of_one_resample_that_draws_every_scene_once_is_the_pooled_miou():
    x = np.array([[[1.0, 0.0], [2.0, 0.0]], [[3.0, 4.0], [6.0, 4.0]]])  # 2 scenes, class 1 absent in scene 0
    sums = _resampled_sums(x, np.array([[0, 1]]))
    assert _miou([sums])[0] == pytest.approx(((1 + 3) / (2 + 6) + 4 / 4) / 2)
