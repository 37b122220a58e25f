"""Fourier-optics PSF of a phase mask in front of a thin lens, landing on the sensor grid.

Pupil field (the paper's eq. 1): U = A(rho) exp(i [2 pi / lambda (n_lambda - 1) h(rho, theta)
+ psi rho^2]), psi = pi R^2 / lambda (1/z_o + 1/z_s - 1/f). PSF(x_s) = |F{U}(x_s / (lambda z_s))|^2
(eq. 2).

Each sensor pixel receives the integral of that intensity over its square, computed exactly for the
sampled pupil rather than by a quadrature: the field of an N-sample pupil is periodic on the sensor
(period lambda z_s / dx = lambda F# N) and its intensity is a trigonometric polynomial with at most
N - 1 harmonics per axis, so L >= 2N - 1 samples per period (one zero-padded FFT of the pupil)
determine it, and the pixel integral of each harmonic is a sinc. Both steps are one fixed real
matrix per axis and wavelength (`pixel_integration_matrix`), cached per geometry: pixels = G I G^T.
A matrix Fourier transform (`mft_kernel`) gives the point-sampled intensity at any sensor position
for the closed-form checks.

The mask thickness h is a Zernike sum (the spec's mask.zernike_um) or a height map read from a file and
sampled on the pupil grid (`encoder_basis`); either way it enters only through the pupil phase.

Sign convention: positive Z2 (x tilt) moves the PSF towards +x (increasing column index), positive
Z3 towards +y (increasing row index).
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from functools import lru_cache
from pathlib import Path

import numpy as np
import torch
from scipy.fft import next_fast_len

from lenses.height_file import max_steps_um, read_height_map, sample_height_map
from lenses.materials import refractive_index
from lenses.measured import sha256_of
from lenses.spec import LensSpec, LensSpecError
from lenses.zernike import max_gradient, zernike_basis

# Window searched beyond the geometric blur radius, in units of lambda F#. The diffraction rings of
# a hard-edged pupil carry energy far out: an in-focus F/5 lens holds 99 % of its energy within
# about 35 px but needs about 260 px for 99.9 % (measured; docs/modelling.md, "PSF support").
DIFFRACTION_MARGIN_LAMBDA_F = 40.0
# A 64-sample pupil leaves 1-2 % L1 error in the PSF from its staircase rim, 128 samples 0.2-0.4 %
# (against 768 samples; the PSF-grid study, docs/modelling.md, finds N = 64 within 1.2 dB of 128).
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


@lru_cache(maxsize=8)
def _height_file(path: str, sha256: str) -> np.ndarray:
    data = read_height_map(path).height_um
    if sha256_of(Path(path)) != sha256:
        raise LensSpecError(f"height_map.file ({path}) changed since the spec was read (height_map.sha256 = "
                            f"{sha256!r}); load the spec again")
    data.setflags(write=False)
    return data


def height_map_um(spec: LensSpec) -> np.ndarray:
    """A height-map spec's glass thickness (n_y, n_x) in um, row 0 at +y, NaN outside the glass (read-only,
    cached per file and content). Raises LensSpecError when the file no longer matches the spec's sha256."""
    if spec.height_map is None:
        raise ValueError(f"lens spec {spec.name!r} is a {spec.kind} lens, not a height map")
    return _height_file(spec.height_map.file, spec.height_map.sha256)


def encoder_coefficients(spec: LensSpec) -> tuple[float, ...]:
    """What `PupilModel` multiplies its basis by: the Zernike coefficients (um), or (1,) for a height map
    (whose basis is the map itself)."""
    return (1.0,) if spec.height_map is not None else spec.mask.zernike_um


def encoder_basis(spec: LensSpec, pupil_samples: int) -> torch.Tensor:
    """Thickness per unit coefficient on the N x N pupil grid, (n, N, N) float64 in um, zero outside the disk:
    the Zernike basis of the mask's n terms, or the height map sampled on the grid (n = 1)."""
    if spec.height_map is None:
        return zernike_basis(len(spec.mask.zernike_um), pupil_samples, dtype=torch.float64)
    radius_um = spec.optics.aperture_diameter_mm * 500.0
    sampled = sample_height_map(height_map_um(spec), spec.height_map.sample_pitch_um, pupil_samples, radius_um)
    return torch.from_numpy(sampled)[None]


def height_map_slope(spec: LensSpec) -> float:
    """Upper bound on |grad h| of a height map in um per unit normalised radius, from the steps between
    neighbouring nodes over the aperture (and one node beyond, which the interpolation at the rim uses)."""
    assert spec.height_map is not None
    heights, pitch = height_map_um(spec), spec.height_map.sample_pitch_um
    n_y, n_x = heights.shape
    yy, xx = np.meshgrid((np.arange(n_y) - (n_y - 1) / 2) * pitch, (np.arange(n_x) - (n_x - 1) / 2) * pitch,
                         indexing="ij")
    radius_um = spec.optics.aperture_diameter_mm * 500.0
    step_x, step_y = max_steps_um(np.where(np.hypot(xx, yy) <= radius_um + 1.5 * pitch, heights, np.nan))
    return math.hypot(step_x, step_y) / pitch * radius_um


def worst_case_coefficients(spec: LensSpec) -> np.ndarray:
    """|c_j| in um to size the grids for: the bounds of a trainable mask, else the coefficients."""
    if spec.mask.bounds_um is not None:
        return np.array([max(abs(lo), abs(hi)) for lo, hi in spec.mask.bounds_um])
    return np.abs(np.array(spec.mask.zernike_um))


def phase_slope_terms(spec: LensSpec) -> np.ndarray:
    """Upper bound on |grad phase| (rad per unit normalised radius), per channel and term.

    Shape (3, n + 1): the n mask terms Z1..Zn (one term for a height map) then the defocus term
    (|grad psi rho^2| <= 2|psi|).
    Their sum per channel bounds the steepest phase slope (triangle inequality).
    """
    c = optical_constants(spec)
    if spec.height_map is not None:
        slopes = np.array([height_map_slope(spec)])
    else:
        coeffs = worst_case_coefficients(spec)
        slopes = coeffs * np.array([max_gradient(j) for j in range(1, len(coeffs) + 1)])
    mask_terms = np.array(c.phase_per_um)[:, None] * slopes[None, :]
    return np.concatenate([mask_terms, 2 * np.abs(np.array(c.defocus_rad))[:, None]], axis=1)


@dataclass(frozen=True)
class Geometry:
    """Grid sizes, fixed once per lens so that nothing changes shape while a mask trains."""

    pupil_samples: int   # N: pupil grid is N x N over the aperture diameter (0: no pupil, a measured PSF)
    psf_size_px: int     # K: PSF support (odd) on the sensor grid

    @property
    def fft_size(self) -> int:
        """L: samples per period of the sensor-plane field, >= 2N - 1 so that |field|^2 does not alias."""
        return next_fast_len(2 * self.pupil_samples - 1)


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
        what = ("the defocus (optics.focus_distance_m vs optics.object_distance_m)" if term == terms.shape[1] - 1
                else "the height map (height_map.file)" if spec.height_map is not None
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


@lru_cache(maxsize=64)
def pixel_integration_matrix(psf_size_px: int, pitch_mm: float, period_mm: float, harmonics: int,
                             fft_size: int) -> np.ndarray:
    """G (K, L), float64: the integral over sensor pixel k of a period_mm-periodic intensity with at
    most `harmonics` harmonics, from its L samples at x_j = j period_mm / L.

    Such an intensity is I(x) = sum_{|l| <= harmonics} a_l exp(2 pi i l x / P) with
    a_l = (1/L) sum_j I(x_j) exp(-2 pi i l x_j / P) (exact for L > 2 harmonics), and the integral of
    each harmonic over the pixel [c_k - p/2, c_k + p/2] is p sinc(l p / P) exp(2 pi i l c_k / P).
    So G[k, j] = (p / L) sum_l sinc(l p / P) cos(2 pi l (c_k - x_j) / P) (in mm), and the pixel
    energies of an (L, L) intensity I are G @ I @ G.T. Pixel K//2 is centred on x = 0.
    """
    if fft_size <= 2 * harmonics:
        raise ValueError(f"fft_size must exceed 2 * harmonics = {2 * harmonics}, got {fft_size}")
    lags = np.arange(-harmonics, harmonics + 1)
    centres = (np.arange(psf_size_px) - psf_size_px // 2) * pitch_mm
    samples = np.arange(fft_size) * period_mm / fft_size
    to_pixels = np.sinc(lags * pitch_mm / period_mm) * np.exp(2j * np.pi * np.outer(centres, lags) / period_mm)
    from_samples = np.exp(-2j * np.pi * np.outer(lags, samples) / period_mm)
    return (to_pixels @ from_samples).real * (pitch_mm / fft_size)


class PixelEnergy(torch.autograd.Function):
    """Mask coefficients (n,) float64 in um -> pixel energies (3, K, K) float64 through `PupilModel`'s
    pupil phase, padded FFT and pixel integration, with a hand-written backward.

    Double precision throughout, though single would halve the cost and change the PSF by < 1e-6 in
    L1: at the co-design start (a flat mask) the PSF's first derivatives with respect to the even
    terms (defocus, astigmatism) are exactly zero, and single-precision rounding noise there is as
    large as Adam's epsilon, so it would push those coefficients by up to one learning rate per step
    in a random direction (and data-parallel ranks would no longer reproduce the single-process run:
    tests/benchmark/codesign/test_ddp.py).

    Autograd through the composite (polar, padded FFT, real/imag, squares, matmuls) spent most of its
    time in elementwise passes over (3, L, L) complex tensors; the backward here makes three (the
    product with the field, the inverse FFT, one pass on the pupil) and reuses the forward's field. A
    backward that must itself be differentiated (create_graph, the gradient penalty) recomputes the
    field from the coefficients with differentiable ops, so second derivatives stay exact.
    """

    @staticmethod
    def forward(ctx, coefficients_um: torch.Tensor, model: "PupilModel") -> torch.Tensor:  # type: ignore[override]
        u, field = model.padded_field(model.pupil_phase(coefficients_um))
        ctx.model = model
        ctx.save_for_backward(coefficients_um, u, field)
        return model.pixels_from_field(field)

    @staticmethod
    def backward(ctx, grad_pixels: torch.Tensor) -> tuple[torch.Tensor, None]:  # type: ignore[override]
        coefficients_um, u, field = ctx.saved_tensors
        model = ctx.model
        if torch.is_grad_enabled():  # create_graph: the gradient must depend on the coefficients differentiably
            u, field = model.padded_field(model.pupil_phase(coefficients_um))
        grad_phase = model.phase_gradient(u, field, grad_pixels)
        # phase = sum_j c_j (2 pi (n - 1) / lambda) Z_j + defocus: the chain rule through the basis.
        grad_thickness = torch.tensordot(model.phase_per_um, grad_phase, dims=1)
        return model.basis.flatten(1) @ grad_thickness.flatten(), None


class PupilModel(torch.nn.Module):
    """Differentiable pupil -> sensor-pixel PSF for the three colour channels of one lens.

    The three wavelengths go through each step as one batch; the FFT size and the pixel
    integration matrices are fixed by the geometry and built once.
    """

    def __init__(self, spec: LensSpec, geometry: Geometry):
        super().__init__()
        c = optical_constants(spec)
        self.constants = c
        self.geometry = geometry
        self.pitch_mm = spec.sensor.pixel_pitch_um * 1e-3
        n = geometry.pupil_samples
        basis = encoder_basis(spec, n)
        coords = (torch.arange(n, dtype=torch.float64) + 0.5) / n * 2 - 1
        rho2 = coords[None, :] ** 2 + coords[:, None] ** 2
        self.register_buffer("basis", basis, persistent=False)
        self.register_buffer("aperture", (rho2 <= 1.0).to(torch.float64), persistent=False)
        self.register_buffer("rho2", rho2, persistent=False)
        self.register_buffer("phase_per_um", torch.tensor(c.phase_per_um, dtype=torch.float64), persistent=False)
        self.register_buffer("defocus", torch.tensor(c.defocus_rad, dtype=torch.float64), persistent=False)
        self.pupil_x_mm = coords * c.aperture_radius_mm
        self.pupil_dx_mm = 2 * c.aperture_radius_mm / n
        # The sensor-plane field of the sampled pupil repeats every lambda z_s / dx.
        self.period_mm = tuple(lam * c.sensor_distance_mm / self.pupil_dx_mm for lam in c.wavelength_mm)
        integration = np.stack([pixel_integration_matrix(geometry.psf_size_px, self.pitch_mm, period, n - 1,
                                                         geometry.fft_size) for period in self.period_mm])
        # The field is the FFT times dx^2; folding that factor into G spares a pass over (3, L, L).
        # Single precision for the two products with G (half the time of double): they are linear
        # in |F|^2, which at a flat mask is even in the even terms sample by sample, so whatever
        # rounding they add to the pixels or to d/d|F|^2 leaves those terms' gradient exactly zero
        # (tests/lenses/test_pixel_energy_backward.py); the field and its adjoint FFT stay double.
        integration = integration * self.pupil_dx_mm**2
        self.register_buffer("integration", torch.from_numpy(integration).to(torch.float32), persistent=False)
        self.register_buffer("wavelength_mm", torch.tensor(c.wavelength_mm, dtype=torch.float64), persistent=False)
        self._mft_kernels: dict[int, torch.Tensor] = {}

    def pupil_phase(self, coefficients_um: torch.Tensor) -> torch.Tensor:
        """Pupil phase (3, N, N) in rad, float64, for coefficients (n,) in um of glass (n terms of the basis)."""
        thickness = torch.einsum("j,jyx->yx", coefficients_um.to(torch.float64), self.basis)
        return self.phase_per_um[:, None, None] * thickness + self.defocus[:, None, None] * self.rho2

    def pupil_field(self, coefficients_um: torch.Tensor) -> torch.Tensor:
        """Complex pupil field U, (3, N, N), complex128, for coefficients (n,) in um of glass."""
        phase = self.pupil_phase(coefficients_um)
        return torch.polar(self.aperture.expand_as(phase), phase)

    def sampled_intensity(self, coefficients_um: torch.Tensor, oversample: int) -> torch.Tensor:
        """|F{U}|^2 at the midpoints of s x s cells of every pixel, (3, K*s, K*s), float64, rows = y.

        A point-sampled intensity for the closed-form checks (Airy zero, Strehl ratios); the PSF
        itself integrates each pixel exactly (`pixel_energy`).
        """
        kernel = self._mft_kernels.get(oversample)
        if kernel is None:
            xs = torch.as_tensor(sample_positions_mm(self.geometry.psf_size_px, oversample, self.pitch_mm))
            kernel = torch.stack([mft_kernel(xs, self.pupil_x_mm, lam, self.constants.sensor_distance_mm)
                                  for lam in self.constants.wavelength_mm]).to(self.basis.device)
            self._mft_kernels[oversample] = kernel
        u = self.pupil_field(coefficients_um)
        field = kernel @ u @ kernel.transpose(1, 2) * self.pupil_dx_mm**2
        return field.real**2 + field.imag**2

    def pixel_energy(self, coefficients_um: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor]:
        """Energy per sensor pixel (3, K, K), the intensity integrated exactly over each pixel, and
        the total energy (3,), both float64 in mm^2 x pupil intensity units (the pixels accurate to
        single precision, ~1e-7 of the peak).

        The field at the L x L sensor positions j lambda z_s / (L dx) of one period is the
        zero-padded FFT of the pupil times dx^2 (times a phase from the grid origin, which |.|^2
        drops). The total comes from Parseval: the integral of |F{U}|^2 over the sensor equals
        (lambda z_s)^2 times the integral of |U|^2 over the pupil, so the ratio of the two is the
        energy fraction that landed inside the K x K crop.
        """
        pixels = PixelEnergy.apply(coefficients_um.to(torch.float64), self)
        total = self.aperture.sum() * self.pupil_dx_mm**2 * (self.wavelength_mm * self.constants.sensor_distance_mm) ** 2
        return pixels, total

    def padded_field(self, phase: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor]:
        """Pupil field U = A exp(i phase) (3, N, N) and the transpose of its zero-padded 2-D FFT,
        (3, L, L) complex128 with rows along x frequency and columns along y frequency.

        Both passes transform along the last (contiguous) axis: the N pupil rows (the other L - N
        are zeros), then, transposed, all L columns. A padded fft2 (a strided pass over a
        power-of-two row length, which thrashes the cache) costs about twice as much.
        """
        u = torch.complex(self.aperture * torch.cos(phase), self.aperture * torch.sin(phase))
        size = self.geometry.fft_size
        return u, torch.fft.fft(torch.fft.fft(u, n=size, dim=-1).transpose(1, 2), n=size, dim=-1)

    def pixels_from_field(self, field_t: torch.Tensor) -> torch.Tensor:
        """Pixel energies G |F|^2 G^T (3, K, K), float64 holding float32-accurate values, from the
        transposed padded FFT (3, L, L).

        The same G integrates both axes, so G |F^T|^2 G^T is the transpose of the pixel energies.
        """
        intensity_t = torch.addcmul(field_t.real.square(), field_t.imag, field_t.imag).to(torch.float32)  # dx^4 is in G
        return (self.integration @ intensity_t @ self.integration.transpose(1, 2)).transpose(1, 2).to(torch.float64)

    def phase_gradient(self, u: torch.Tensor, field_t: torch.Tensor, grad_pixels: torch.Tensor) -> torch.Tensor:
        """Vector-Jacobian product of pixel energies -> pupil phase: d loss / d phase (3, N, N) for
        d loss / d pixels (3, K, K), from `padded_field`'s outputs.

        pixels = G |F|^2 G^T gives d/d|F|^2 = G^T grad G; |F|^2 gives 2 Re(conj(F) dF); the padded FFT's
        adjoint is L^2 times the inverse FFT cropped to the pupil (norm="forward": unscaled inverse),
        taken like the forward along the last axis (y frequency, cropped to the N pupil rows, then
        transposed back, x); U = A exp(i phase) gives d/d phase = Im(conj(U) d/dU) (torch's
        conjugate convention).
        """
        n = self.geometry.pupil_samples
        grad_pixels_t = grad_pixels.transpose(1, 2).to(torch.float32)
        grad_intensity_t = self.integration.transpose(1, 2) @ grad_pixels_t @ self.integration
        # Cast first: torch's real-times-complex kernel is several times slower than complex-times-complex.
        grad_field_t = field_t * grad_intensity_t.to(field_t.dtype)
        grad_rows = torch.fft.ifft(grad_field_t, dim=-1, norm="forward")[..., :n].transpose(1, 2)
        grad_u = torch.fft.ifft(grad_rows, dim=-1, norm="forward")[..., :n]
        return 2 * (u.real * grad_u.imag - u.imag * grad_u.real)

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
    k0 = initial_support_px(spec)
    probe = PupilModel(spec, Geometry(pupil_samples_for(spec, k0), k0))
    coeffs = torch.tensor(encoder_coefficients(spec), dtype=torch.float64)
    # A trainable mask is sized from its bounds alone, not from where it starts: the diffraction
    # support of the unmasked lens widened by the worst-case geometric blur diameter.
    probe_coeffs = torch.zeros_like(coeffs) if spec.mask.trainable else coeffs
    with torch.no_grad():
        pixels, total = probe.pixel_energy(probe_coeffs)
    k = energy_support(pixels, total, spec.simulation.psf_energy_fraction)
    if spec.mask.trainable:
        k = min(_odd(k + 2 * geometric_radius_px(spec)), spec.simulation.max_psf_size_px)
    geometry = Geometry(pupil_samples_for(spec, k), k)
    with torch.no_grad():
        _, fraction = PupilModel(spec, geometry)(coeffs)
    return geometry, fraction
