"""Fourier-optics PSF of a phase mask in front of a thin lens, landing on the sensor grid.

Pupil field (DESIGN.md, paper eq. 1): U = A(rho) exp(i [2 pi / lambda (n_lambda - 1) h(rho, theta)
+ psi rho^2]), psi = pi R^2 / lambda (1/z_o + 1/z_s - 1/f). PSF(x_s) = |F{U}(x_s / (lambda z_s))|^2
(eq. 2), evaluated by a matrix Fourier transform (MFT) straight at the sensor sub-pixel positions:
exact sampling per wavelength and only the K x K support that is needed.

Sign convention: positive Z2 (x tilt) moves the PSF towards +x (increasing column index), positive
Z3 towards +y (increasing row index).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
import torch

from lenses.materials import refractive_index
from lenses.spec import N_ZERNIKE, LensSpec, LensSpecError
from lenses.zernike import max_gradient, zernike_basis

# Window searched beyond the geometric blur radius, in units of lambda F#. The diffraction rings of
# a hard-edged pupil carry energy far out: an in-focus F/5 lens holds 99 % of its energy within
# about 35 px but needs about 260 px for 99.9 % (measured; see README "Modelling choices").
DIFFRACTION_MARGIN_LAMBDA_F = 40.0
# A 64-sample pupil leaves 1-2 % L1 error in the PSF from its staircase rim, 128 samples 0.2-0.4 %
# (against 768 samples; measured in tests/benchmarks/test_modelling_choices.py).
MIN_PUPIL_SAMPLES = 128


@dataclass(frozen=True)
class OpticalConstants:
    """Per-channel optical constants derived from a spec (all lengths in mm, phases in rad)."""

    wavelength_mm: tuple[float, ...]
    index: tuple[float, ...]            # mask refractive index per channel
    phase_per_um: tuple[float, ...]     # 2 pi (n - 1) / lambda: phase of 1 um of glass
    defocus_rad: tuple[float, ...]      # psi: phase at the pupil rim from defocus
    sensor_distance_mm: float
    aperture_radius_mm: float
    f_number: float                     # working F-number z_s / D


def optical_constants(spec: LensSpec) -> OpticalConstants:
    o = spec.optics
    f = o.focal_length_mm
    z_s = 1.0 / (1.0 / f - 1.0 / (o.focus_distance_m * 1000.0))
    z_o = o.object_distance_m * 1000.0
    radius = o.aperture_diameter_mm / 2.0
    lam = tuple(w * 1e-6 for w in o.wavelengths_nm)
    n = tuple(refractive_index(o.mask_material, w) for w in o.wavelengths_nm)
    return OpticalConstants(
        wavelength_mm=lam,
        index=n,
        phase_per_um=tuple(2 * math.pi * (ni - 1.0) / (w * 1e3) for ni, w in zip(n, lam)),
        defocus_rad=tuple(math.pi * radius**2 / w * (1 / z_o + 1 / z_s - 1 / f) for w in lam),
        sensor_distance_mm=z_s,
        aperture_radius_mm=radius,
        f_number=z_s / o.aperture_diameter_mm,
    )


def worst_case_coefficients(spec: LensSpec) -> np.ndarray:
    """|c_j| in um to size the grids for: the bounds of a trainable mask, else the coefficients."""
    if spec.mask.bounds_um is not None:
        return np.array([max(abs(lo), abs(hi)) for lo, hi in spec.mask.bounds_um])
    return np.abs(np.array(spec.mask.zernike_um))


def phase_slope_terms(spec: LensSpec) -> np.ndarray:
    """Upper bound on |grad phase| (rad per unit normalised radius), per channel and term.

    Shape (3, N_ZERNIKE + 1): the mask terms Z1..Z6 then the defocus term (|grad psi rho^2| <= 2|psi|).
    Their sum per channel bounds the steepest phase slope (triangle inequality).
    """
    c = optical_constants(spec)
    coeffs = worst_case_coefficients(spec)
    grads = np.array([max_gradient(j) for j in range(1, N_ZERNIKE + 1)])
    mask_terms = np.array(c.phase_per_um)[:, None] * (coeffs * grads)[None, :]
    return np.concatenate([mask_terms, 2 * np.abs(np.array(c.defocus_rad))[:, None]], axis=1)


@dataclass(frozen=True)
class Geometry:
    """Grid sizes, fixed once per lens so that nothing changes shape while a mask trains."""

    pupil_samples: int   # N: pupil grid is N x N over the aperture diameter
    psf_size_px: int     # K: PSF support (odd) on the sensor grid
    oversample: int      # s: sub-samples per pixel side


def _odd(x: float) -> int:
    k = int(math.ceil(x))
    return k if k % 2 == 1 else k + 1


def pupil_samples_for(spec: LensSpec, psf_size_px: int) -> int:
    """Smallest even N with at most pi phase change per pupil sample and a wide enough MFT period.

    Raises LensSpecError naming the coefficient that dominates the slope when N would exceed
    spec.simulation.max_pupil_samples (rather than aliasing silently).
    """
    c = optical_constants(spec)
    terms = phase_slope_terms(spec)
    slope = terms.sum(axis=1)  # rad per unit rho, per channel
    # Grid spacing in rho is 2/N: need slope * 2 / N <= pi.
    n_slope = 2.0 * slope.max() / math.pi
    # The MFT of a grid with spacing D/N repeats every lambda F# N on the sensor: the support must fit.
    lam_min = min(c.wavelength_mm)
    n_period = psf_size_px * spec.sensor.pixel_pitch_um * 1e-3 / (lam_min * c.f_number)
    n = int(math.ceil(max(n_slope * 1.25, n_period * 1.1, MIN_PUPIL_SAMPLES)))
    n += n % 2
    limit = spec.simulation.max_pupil_samples
    if n > limit:
        ch, term = np.unravel_index(np.argmax(terms), terms.shape)
        what = ("the defocus (optics.focus_distance_m vs optics.object_distance_m)" if term == N_ZERNIKE
                else f"mask coefficient Z{term + 1} (mask.zernike_um[{term}] or its bound)")
        raise LensSpecError(
            f"{what} is too strong for the pupil grid: the phase slope reaches {slope.max():.0f} rad per unit"
            f" radius at {spec.optics.wavelengths_nm[ch]:.0f} nm, which needs {n} pupil samples but"
            f" simulation.max_pupil_samples = {limit}; reduce it or raise the limit"
        )
    return n


def geometric_radius_px(spec: LensSpec) -> float:
    """Upper bound on the geometric blur radius in pixels, from the phase-slope bound.

    A ray leaving the pupil where the phase slope is g (rad per unit rho) lands
    lambda z_s g / (2 pi R) away from the axis.
    """
    c = optical_constants(spec)
    slope = phase_slope_terms(spec).sum(axis=1)
    radius_mm = max(lam * c.sensor_distance_mm * g / (2 * math.pi * c.aperture_radius_mm)
                    for lam, g in zip(c.wavelength_mm, slope))
    return radius_mm / (spec.sensor.pixel_pitch_um * 1e-3)


def initial_support_px(spec: LensSpec) -> int:
    """Odd K bounding the search window: geometric blur radius plus a diffraction margin."""
    c = optical_constants(spec)
    margin_px = DIFFRACTION_MARGIN_LAMBDA_F * max(c.wavelength_mm) * c.f_number / (spec.sensor.pixel_pitch_um * 1e-3)
    return min(_odd(2 * (geometric_radius_px(spec) + margin_px) + 1), spec.simulation.max_psf_size_px)


def sample_positions_mm(psf_size_px: int, oversample: int, pitch_mm: float) -> np.ndarray:
    """Sensor positions (mm) of the K*s sub-samples: midpoints of s x s cells in each pixel.

    Pixel K//2 is centred on the optical axis, so an ideal PSF peaks at [K//2, K//2].
    """
    k, s = psf_size_px, oversample
    pixel = np.arange(k) - k // 2
    sub = (np.arange(s) + 0.5) / s - 0.5
    return ((pixel[:, None] + sub[None, :]) * pitch_mm).reshape(-1)


def mft_kernel(positions_mm: torch.Tensor, pupil_x_mm: torch.Tensor, wavelength_mm: float,
               sensor_distance_mm: float) -> torch.Tensor:
    """Matrix Fourier transform kernel exp(-2 pi i x_s x_p / (lambda z_s)), shape (M, N).

    field = kernel @ U @ kernel.T * dx^2 evaluates the Fraunhofer field of a pupil U (N, N) with
    sample spacing dx at the M x M sensor positions (rows y, columns x).
    """
    arg = -2 * math.pi / (wavelength_mm * sensor_distance_mm) * positions_mm[:, None] * pupil_x_mm[None, :]
    return torch.polar(torch.ones_like(arg), arg)


class PupilModel(torch.nn.Module):
    """Differentiable pupil -> sensor-grid PSF for the three colour channels of one lens."""

    def __init__(self, spec: LensSpec, geometry: Geometry):
        super().__init__()
        c = optical_constants(spec)
        self.constants = c
        self.geometry = geometry
        n = geometry.pupil_samples
        basis = zernike_basis(N_ZERNIKE, n, dtype=torch.float64)
        coords = (torch.arange(n, dtype=torch.float64) + 0.5) / n * 2 - 1
        rho2 = coords[None, :] ** 2 + coords[:, None] ** 2
        self.register_buffer("basis", basis, persistent=False)
        self.register_buffer("aperture", (rho2 <= 1.0).to(torch.float64), persistent=False)
        self.register_buffer("rho2", rho2, persistent=False)
        self.register_buffer("phase_per_um", torch.tensor(c.phase_per_um, dtype=torch.float64), persistent=False)
        self.register_buffer("defocus", torch.tensor(c.defocus_rad, dtype=torch.float64), persistent=False)
        self.pupil_x_mm = coords * c.aperture_radius_mm
        self.pupil_dx_mm = 2 * c.aperture_radius_mm / n
        xs = torch.as_tensor(sample_positions_mm(geometry.psf_size_px, geometry.oversample,
                                                 spec.sensor.pixel_pitch_um * 1e-3))
        self.sample_dx_mm = spec.sensor.pixel_pitch_um * 1e-3 / geometry.oversample
        kernel = torch.stack([mft_kernel(xs, self.pupil_x_mm, lam, c.sensor_distance_mm) for lam in c.wavelength_mm])
        self.register_buffer("kernel", kernel, persistent=False)  # (3, K*s, N)
        self.register_buffer("wavelength_mm", torch.tensor(c.wavelength_mm, dtype=torch.float64), persistent=False)

    def pupil_field(self, coefficients_um: torch.Tensor) -> torch.Tensor:
        """Complex pupil field U, (3, N, N), for coefficients (6,) in um of glass."""
        thickness = torch.einsum("j,jyx->yx", coefficients_um.to(torch.float64), self.basis)
        phase = self.phase_per_um[:, None, None] * thickness + self.defocus[:, None, None] * self.rho2
        return torch.polar(self.aperture.expand_as(phase), phase)

    def sampled_intensity(self, coefficients_um: torch.Tensor) -> torch.Tensor:
        """|F{U}|^2 at the K*s x K*s sub-pixel positions, (3, K*s, K*s), float64, rows = y."""
        u = self.pupil_field(coefficients_um)
        field = self.kernel @ u @ self.kernel.transpose(1, 2) * self.pupil_dx_mm**2
        return field.real**2 + field.imag**2

    def pixel_energy(self, coefficients_um: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor]:
        """Energy per sensor pixel (3, K, K) (s x s sub-samples summed) and the total energy (3,).

        The total comes from Parseval: the integral of |F{U}|^2 over the sensor equals
        (lambda z_s)^2 times the integral of |U|^2 over the pupil, so the ratio of the two is the
        energy fraction that landed inside the K x K crop.
        """
        k, s = self.geometry.psf_size_px, self.geometry.oversample
        pixels = self.sampled_intensity(coefficients_um).reshape(3, k, s, k, s).sum(dim=(2, 4)) * self.sample_dx_mm**2
        total = self.aperture.sum() * self.pupil_dx_mm**2 * (self.wavelength_mm * self.constants.sensor_distance_mm) ** 2
        return pixels, total

    def forward(self, coefficients_um: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor]:
        """PSF (3, K, K) float32, each channel summing to 1, and the energy fraction (3,) inside it."""
        pixels, total = self.pixel_energy(coefficients_um)
        inside = pixels.sum(dim=(1, 2))
        return (pixels / inside[:, None, None]).to(torch.float32), (inside / total).to(torch.float32)


def energy_support(psf_unnormalised: torch.Tensor, total: torch.Tensor, fraction: float) -> int:
    """Smallest odd centred crop of a (3, K, K) pixel PSF holding `fraction` of `total` in every channel."""
    k = psf_unnormalised.shape[-1]
    for size in range(1, k + 1, 2):
        lo = k // 2 - size // 2
        crop = psf_unnormalised[:, lo:lo + size, lo:lo + size].sum(dim=(1, 2))
        if bool((crop >= fraction * total).all()):
            return size
    return k


def choose_geometry(spec: LensSpec) -> tuple[Geometry, torch.Tensor]:
    """Pupil grid N and PSF support K for a spec, and the energy fraction captured at that K.

    K is the smallest odd crop holding simulation.psf_energy_fraction of the energy of every
    channel. Trainable masks widen it by the worst-case geometric blur allowed by their bounds, so
    that it never changes while the mask trains.
    """
    s = spec.simulation.oversample
    k0 = initial_support_px(spec)
    probe = PupilModel(spec, Geometry(pupil_samples_for(spec, k0), k0, s))
    coeffs = torch.tensor(spec.mask.zernike_um, dtype=torch.float64)
    # A trainable mask is sized from its bounds alone, not from where it starts: the diffraction
    # support of the unmasked lens widened by the worst-case geometric blur diameter.
    probe_coeffs = torch.zeros_like(coeffs) if spec.mask.trainable else coeffs
    with torch.no_grad():
        pixels, total = probe.pixel_energy(probe_coeffs)
    k = energy_support(pixels, total, spec.simulation.psf_energy_fraction)
    if spec.mask.trainable:
        k = min(_odd(k + 2 * geometric_radius_px(spec)), spec.simulation.max_psf_size_px)
    geometry = Geometry(pupil_samples_for(spec, k), k, s)
    with torch.no_grad():
        _, fraction = PupilModel(spec, geometry)(coeffs)
    return geometry, fraction
