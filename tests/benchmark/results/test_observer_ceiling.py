"""The ideal observer's ceiling against closed forms and invariants."""

from __future__ import annotations

import math

import numpy as np
import pytest
import torch
from scipy.stats import norm

import lenses
from benchmark.results.observer.ceiling import (Camera, CeilingCurve, PlateModel, Precision, ceiling_curves, certified_width, hypothesis_means,
                                                ideal_accuracy, position_accuracies)

MODEL = PlateModel()


def camera(psf: torch.Tensor, electrons: float, read_noise_e: float) -> Camera:
    return Camera(psf.to(torch.float64), torch.full((3,), electrons, dtype=torch.float64), read_noise_e)


def delta_psf() -> torch.Tensor:
    return torch.ones(3, 1, 1)


def test_no_blur_and_no_noise_reads_every_character():
    # 1e9 e- per unit radiance and no read noise: relative shot noise ~ 3e-5, nothing is confusable.
    acc = position_accuracies(camera(delta_psf(), 1e9, 0.0), 24, (1,), MODEL, 2, 2, np.random.default_rng(0))
    np.testing.assert_allclose(acc, 1.0, atol=1e-9)


def test_identical_hypotheses_give_chance_exactly():
    means = torch.full((26, 50), 300.0, dtype=torch.float64)
    assert ideal_accuracy(means, 2.0, 1, 10, np.random.default_rng(0)) == (1 / 26, 1 / 26)


def test_uniform_psf_destroys_the_characters():
    # A 61 x 61 uniform PSF on a 12 px plate spreads every glyph's light evenly: what is left is the
    # glyph's total ink, buried in the noise of the whole plate's light.
    psf = torch.ones(3, 61, 61) / 61**2
    acc = position_accuracies(camera(psf, 50.0, 2.0), 12, (1,), MODEL, 4, 4, np.random.default_rng(1))
    letters, digits = acc[:, 0, [0, 1, 5, 6]].mean(), acc[:, 0, [2, 3, 4]].mean()
    assert letters == pytest.approx(1 / 26, abs=0.01)
    assert digits == pytest.approx(1 / 10, abs=0.02)


@pytest.mark.parametrize("frames", [1, 4])
def test_two_glyphs_in_white_gaussian_noise_match_phi_of_half_the_distance(frames):
    # Read noise 1e5 e- against <= 3e6 e- of signal: white Gaussian noise to 3e-4 in variance.
    gauss = torch.exp(-(torch.arange(-3, 4.0) ** 2) / 4)
    psf = (gauss[:, None] * gauss[None, :]).expand(3, 7, 7) / (gauss.sum() ** 2)
    means = hypothesis_means(camera(psf, 3e6, 1e5), ["AB123CD", "AB128CD"], 16, MODEL)
    sigma = math.sqrt(1e5**2 + float(means.mean()))
    d = float(torch.linalg.norm(means[0] - means[1])) / sigma * math.sqrt(frames)
    assert 0.5 < d < 4  # a test between chance and certainty
    expected = norm.cdf(d / 2)
    posterior, hits = ideal_accuracy(means, 1e5, frames, 20000, np.random.default_rng(2))
    assert posterior == pytest.approx(expected, abs=0.01)
    assert hits == pytest.approx(expected, abs=0.01)


@pytest.fixture(scope="module")
def defocus_curves() -> list[CeilingCurve]:
    coarse = Precision(interval_width=0.1, coarse_width=0.2, min_plates=3, batch=3, max_plates=3)
    return ceiling_curves(lenses.load("defocus"), (6, 12), frames=(1, 8), precision=coarse, seed=0)


@pytest.mark.slow
def test_more_frames_never_lower_the_ceiling(defocus_curves):
    one, eight = defocus_curves
    # Same plate draws for both frame counts; 8 frames average the noise down by sqrt(8).
    assert (eight.position_ceiling > one.position_ceiling).all()
    assert (eight.plate_ceiling > one.plate_ceiling).all()


@pytest.mark.slow
def test_plate_ceiling_is_the_least_block_and_certified_width_follows_it(defocus_curves):
    curve = defocus_curves[0]
    np.testing.assert_array_equal(curve.plate_ceiling, np.fmin(curve.position_ceiling.min(1), curve.pair_ceiling))
    # A right pair has both its characters right: c_pair <= min(c_0, c_1) (up to Monte-Carlo error).
    assert (curve.pair_ceiling <= curve.position_ceiling[:, :2].min(1) + 0.03).all()
    # Near chance the pair certifies what no single letter can (1/26 = 3.8 %): defocus at 6 px.
    assert curve.pair_ceiling[0] < 1 / 26
    assert (curve.plate_ceiling <= curve.char_ceiling).all()
    low, high = curve.plate_interval.T
    assert ((low <= curve.plate_ceiling) & (curve.plate_ceiling <= high)).all()
    eps_between = float(curve.plate_ceiling.mean())
    assert certified_width(curve, eps=float(curve.plate_ceiling.max()) + 1e-9) == 12
    assert certified_width(curve, eps=float(curve.plate_ceiling.min()) - 1e-9) == 0
    assert certified_width(curve, eps=eps_between) in (0, 6)


def test_widths_and_frames_are_validated():
    with pytest.raises(ValueError, match="widths"):
        ceiling_curves(lenses.load("ideal"), (2,))
    with pytest.raises(ValueError, match="frame"):
        ceiling_curves(lenses.load("ideal"), (16,), frames=(0,))
