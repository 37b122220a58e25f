"""The plate-spectrum estimator: a known pattern at every plate size, and the training plates."""

import numpy as np
import pytest

import benchmark.scenes.plate_spectrum as ps
from benchmark.scenes.plate_spectrum import PLATE_ASPECT, estimate_plate_spectrum, spectrum_from_crops


def cosine_plate(width: int, cycles: int, aspect: float = PLATE_ASPECT) -> np.ndarray:
    """A plate whose content is cos(2 pi cycles u) in plate coordinates u in [0, 1), amplitude 0.2."""
    height = max(1, round(width / aspect))
    u = (np.arange(width) + 0.5) / width
    row = 0.5 + 0.2 * np.cos(2 * np.pi * cycles * u)
    return np.repeat(np.repeat(row[None, :, None], height, axis=0), 3, axis=2)


def test_content_fixed_in_plate_coordinates_lands_on_one_frequency_at_every_size():
    """D is in cycles per plate width: the same pattern at 32, 64 and 128 px gives one peak at nu = 6."""
    spectrum = spectrum_from_crops([cosine_plate(w, 6) for w in (32, 64, 128) for _ in range(3)], nx=32)
    ny, nx = (spectrum.table.shape[1] - 1) // 2, (spectrum.table.shape[2] - 1) // 2
    centre_row = spectrum.table[0, ny]
    assert int(np.argmax(centre_row[nx:])) == 6
    # Parseval: the density integrates to the pattern's variance 0.2^2 / 2, whatever the crop sizes.
    assert spectrum.variance()[0] == pytest.approx(0.02, rel=0.1)
    np.testing.assert_allclose(spectrum.mean_radiance, 0.5, atol=1e-6)


def test_least_radiance_is_the_darkest_pixel_of_any_crop_per_channel():
    """The bound's noise level (lenses.bound): the minimum over all crops, each channel on its own."""
    crops = [cosine_plate(32, 3), cosine_plate(64, 5)]
    crops[1][2, 7] = (0.11, 0.9, 0.4)  # one dark red pixel in the second crop
    spectrum = spectrum_from_crops(crops, nx=32)
    expected = np.min([c.reshape(-1, 3).min(axis=0) for c in crops], axis=0)
    np.testing.assert_allclose(spectrum.min_radiance, expected)
    assert spectrum.min_radiance[0] == pytest.approx(0.11)
    assert spectrum.noise_radiance() == spectrum.min_radiance


def test_cached_spectrum_keeps_the_least_radiance(tmp_path, monkeypatch):
    fake = spectrum_from_crops([cosine_plate(w, 4) for w in (32, 64)], nx=32)
    monkeypatch.setattr(ps, "estimate_plate_spectrum", lambda n, size, seed: fake)
    first = ps.cached_plate_spectrum(tmp_path, 3)
    monkeypatch.setattr(ps, "estimate_plate_spectrum", lambda n, size, seed: pytest.fail("not read from the cache"))
    again = ps.cached_plate_spectrum(tmp_path, 3)
    assert again.min_radiance == pytest.approx(first.min_radiance) and again.min_radiance is not None


def test_pixel_density_scales_with_plate_width():
    """S_w(f) = w^2 D(w f): variance seen on the sensor grid grows with w up to the content's variance."""
    spectrum = spectrum_from_crops([cosine_plate(w, 6) for w in (32, 64)], nx=32)
    seen = [float(spectrum.pixel_density(w, 256).mean(dim=(1, 2))[0]) for w in (4, 8, 16, 32)]
    assert seen[0] < 0.3 * seen[-1]  # at 4 px the 6-cycle pattern lies beyond the sensor's Nyquist
    assert seen[-1] == pytest.approx(0.02, rel=0.15)


@pytest.mark.slow
def test_training_plates_give_a_falling_spectrum_and_use_only_the_train_split(monkeypatch):
    splits = []
    real = ps.load_scene

    def spy(scene_set, split, index, size, seed):
        splits.append(split)
        return real(scene_set, split, index, size, seed)

    monkeypatch.setattr(ps, "load_scene", spy)
    spectrum = estimate_plate_spectrum(n_scenes=40)
    assert set(splits) == {"train"} and len(splits) == 40
    assert spectrum.n_crops >= 40
    assert np.all(spectrum.table > 0)
    assert 2.0 < spectrum.tail_exponent < 5.0  # edges and strokes: between smooth and white
    assert all(0.2 < m < 0.9 for m in spectrum.mean_radiance)
    ny, nx = (spectrum.table.shape[1] - 1) // 2, (spectrum.table.shape[2] - 1) // 2
    vy = (np.arange(2 * ny + 1) - ny)[:, None] * spectrum.aspect
    radius = np.hypot(vy, (np.arange(2 * nx + 1) - nx)[None, :])
    low = spectrum.table[1][(radius >= 2) & (radius <= 4)].mean()
    high = spectrum.table[1][(radius >= 48) & (radius <= 64)].mean()
    assert low > 10 * high  # flat up to the strokes (~16 cycles per plate width), then falling


def test_no_crops_is_a_clear_error():
    with pytest.raises(ValueError, match="no plate crops"):
        spectrum_from_crops([])
