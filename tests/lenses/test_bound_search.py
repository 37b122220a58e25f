"""The W_eps search (a very dark lens once made it build ~14 000 x 14 000 matrices for hours):
its trace bound against the matrices it replaces, the same widths and rows as the exact one-pixel-at-a-time
search for normal lenses, and a dark lens certified without a single block matrix."""

import dataclasses
import sys
from pathlib import Path

import pytest
import torch

from lenses import Lens
from lenses import bound
from lenses.bound import (CERTIFY_MAX_PIXELS, _content_covariance, _psf_gram, bound_row, certify_width, fano_ceiling,
                          noise_to_signal, plate_bits, plate_bits_per_channel, trace_bound_bits_per_channel)
from lenses.builtin import SPEC_DIR
from lenses.spec import load_spec

sys.path.insert(0, str(Path(__file__).parent))
from test_bound import ENTROPY, smooth_spectrum  # noqa: E402


def builtin(name: str, white_level_photons: float | None = None, aperture_mm: float | None = None) -> Lens:
    spec = load_spec(SPEC_DIR / f"{name}.toml")
    if white_level_photons is not None:
        spec = dataclasses.replace(spec, sensor=dataclasses.replace(spec.sensor, white_level_photons=white_level_photons))
    if aperture_mm is not None:
        spec = dataclasses.replace(spec, optics=dataclasses.replace(spec.optics, aperture_diameter_mm=aperture_mm))
    return Lens(spec)


def exact_search(psf, spectrum, nsr, entropy_bits, eps, max_width_px=256) -> int:
    """The search as it was: the exact block bound at every width, one pixel at a time, to the first failure."""
    width = 0
    while width < max_width_px:
        if fano_ceiling(float(plate_bits(psf, spectrum, width + 1, nsr, method="block")), entropy_bits) > eps:
            break
        width += 1
    return width


@pytest.mark.parametrize("width", [1, 5, 12])
def test_trace_bound_is_jensen_on_the_trace_of_the_block_matrices(width):
    spectrum, cam = smooth_spectrum(), builtin("defocus", white_level_photons=30.0)
    psf, nsr = cam.psf().detach(), noise_to_signal(cam, spectrum.noise_radiance())
    height = bound.plate_height_px(width, spectrum.aspect)
    n = width * height
    product = _content_covariance(spectrum, width, height) @ _psf_gram(psf, width, height)
    trace = torch.diagonal(product, dim1=-2, dim2=-1).sum(-1) / nsr
    torch.testing.assert_close(trace_bound_bits_per_channel(psf, spectrum, width, nsr),
                               n / 2 * torch.log2(1 + trace / n), rtol=1e-10, atol=0)
    # Never below the block bound (equal, up to rounding, for a 1 px plate: one eigenvalue).
    assert bool((trace_bound_bits_per_channel(psf, spectrum, width, nsr)
                 >= plate_bits_per_channel(psf, spectrum, width, nsr, "block") * (1 - 1e-12)).all())


@pytest.mark.slow
def test_normal_lenses_get_the_widths_and_rows_of_the_exact_search():
    spectrum = smooth_spectrum()
    by_trace = 0
    for name in ("ideal", "defocus"):
        for photons in (None, 30.0, 3.0):
            cam = builtin(name, photons)
            psf = cam.psf().detach()
            for eps in (0.05, 0.3, 0.9):
                row = bound_row(cam, spectrum, ENTROPY, widths_px=(8, 16), eps=eps, frames=(1, 4))
                for t in (1, 4):
                    nsr = noise_to_signal(cam, spectrum.noise_radiance(), t)
                    certificate = certify_width(psf, spectrum, nsr, ENTROPY, eps)
                    assert row[f"bound_width_eps_t{t}"] == exact_search(psf, spectrum, nsr, ENTROPY, eps)
                    assert certificate.limited_at is None and f"bound_width_eps_note_t{t}" not in row
                    by_trace += len(certificate.trace_widths)
                    for w in (8, 16):
                        assert row[f"bound_bits_w{w}_t{t}"] == pytest.approx(float(plate_bits(psf, spectrum, w, nsr)),
                                                                             rel=1e-9)
    assert by_trace > 0, "some width must have been certified by the trace bound, or the comparison proves nothing"


@pytest.mark.slow
def test_a_very_dark_lens_is_certified_without_building_block_matrices(monkeypatch):
    spectrum = smooth_spectrum()
    dark = builtin("ideal", aperture_mm=0.01)  # that lens: 2.7e-6 of the light per unit radiance
    built: list[int] = []
    original = bound._psf_gram
    monkeypatch.setattr(bound, "_psf_gram", lambda psf, w, h: (built.append(w * h), original(psf, w, h))[1])
    traced: list[int] = []
    trace = bound.sigma_gram_trace
    monkeypatch.setattr(bound, "sigma_gram_trace", lambda psf, s, w: (traced.append(w), trace(psf, s, w))[1])
    psf, nsr = dark.psf().detach(), noise_to_signal(dark, spectrum.noise_radiance())
    traces: dict = {}
    certificate = certify_width(psf, spectrum, nsr, ENTROPY, max_width_px=96, traces=traces)
    assert certificate.width == 96 and certificate.limited_at is None  # every width certified
    assert certificate.exact_widths == () and built == []              # by the trace bound alone
    assert traced == list(range(1, 97))
    # A second frame count (bound_row's T = 30) reuses each width's trace: nothing is computed again.
    video = certify_width(psf, spectrum, noise_to_signal(dark, spectrum.noise_radiance(), 30), ENTROPY,
                          max_width_px=96, traces=traces)
    assert video.width == 96 and traced == list(range(1, 97)) and built == []


def test_a_width_beyond_the_matrix_cap_ends_the_search_with_a_lower_bound(monkeypatch, caplog):
    """A lens the trace bound cannot certify and whose exact block grows past the cap: the search
    stops there, the width is a lower bound on the exact search's, and the row says so."""
    spectrum, cam = smooth_spectrum(), builtin("defocus", white_level_photons=3.0)
    psf, nsr = cam.psf().detach(), noise_to_signal(cam, spectrum.noise_radiance())
    eps = 0.9
    uncapped = exact_search(psf, spectrum, nsr, ENTROPY, eps)
    cap = 4 * bound.plate_height_px(4, spectrum.aspect)  # the block of a 4 px plate
    monkeypatch.setattr(bound, "CERTIFY_MAX_PIXELS", cap)
    certificate = certify_width(psf, spectrum, nsr, ENTROPY, eps)
    assert uncapped > 4, "the case must need the exact bound beyond the cap"
    assert certificate.limited_at is not None and certificate.width < certificate.limited_at
    assert certificate.width <= uncapped
    assert all(w * bound.plate_height_px(w, spectrum.aspect) <= cap for w in certificate.exact_widths)
    row = bound_row(cam, spectrum, ENTROPY, widths_px=(8,), eps=eps, frames=(1,))
    assert "a lower bound" in row["bound_width_eps_note_t1"] and f"cap {cap} px" in row["bound_width_eps_note_t1"]
    assert "a lower bound" in caplog.text
    assert CERTIFY_MAX_PIXELS == bound.BLOCK_MAX_PIXELS  # the default cap is the block bound's own


@pytest.mark.parametrize("width, size", [(3, 64), (17, 128), (100, 512), (256, 1024)])
def test_separable_pixel_density_is_the_density_on_the_grid(width, size):
    """`pixel_density` (separable) against its definition w^2 D(w f) through `density` point by point,
    on a spectrum with a table and a tail, so every bound number is the earlier code's within rounding."""
    spectrum = smooth_spectrum()
    f = torch.fft.fftfreq(size, dtype=torch.float64)
    reference = width**2 * spectrum.density(width * f[:, None], width * f[None, :])
    torch.testing.assert_close(spectrum.pixel_density(width, size), reference, rtol=1e-12, atol=0)
