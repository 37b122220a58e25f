"""Attack-independent privacy bound: how many bits of a licence plate can any attacker get?

The lens and sensor are linearised: y_c = g_c (h_c * x_c) + n_c, with g_c = lens.gain() the sensor
value per unit radiance, h_c the pixel-sampled PSF and n_c white Gaussian noise. Shot noise is
signal-dependent (variance e_c L + read^2 electrons at radiance L), so the noise level is chosen
where it is smallest: at the least radiance L_min,c the plate can show (`PlateSpectrum.min_radiance`,
the minimum over the sharp plate crops per channel; 0, read noise alone, when it was not measured).
Every pixel of the plate then has at least that noise, and replacing each pixel's noise by its
least possible variance can only add information (a noisier Gaussian observation is the less noisy
one plus independent noise), so B stays an upper bound. What this neglects, stated: the shot noise
also carries information through its variance (it grows with the mean); per pixel that adds
1 / (2 v) to the Fisher information 1 / v about the mean (v in electrons^2), a relative
1 / (2 (e_c L_min + read^2)) <= 1 / (2 read^2) = 12.5 % at the darkest possible pixel and
0.15 % on the plates' ink (L ~ 0.05). (The earlier operating level, the MEAN plate radiance, was
not conservative: dark ink is up to ~3x less noisy in variance than the mean.) Dividing by g_c puts
signal and noise in radiance units: nsr_c = (e_c L_min,c + read^2) / e_c^2, divided by T for T
frames of a static plate (their mean is a sufficient statistic).

Plate content x_c is modelled by its power spectrum (`PlateSpectrum`): at plate width w px the
per-pixel density is S_w(f) = w^2 D(w f), where D is the density in cycles per plate width, so a
plate twice as wide puts the same content at half the spatial frequency. Under a covariance
constraint a Gaussian input maximises mutual information, so

- rate (large-plate limit): I_c = mean over the Nyquist square of 1/2 log2(1 + |H_c(f)|^2 S_w,c(f) / nsr_c)
  bits per pixel, H_c the optical transfer function (DFT of the pixel-sampled PSF);
- block (exact for a w x h plate): I_c = 1/2 log2 det(I + Sigma_c G_c / nsr_c), Sigma_c the content
  covariance over the plate's w h pixels and G_c = H_c^T H_c the Gram matrix of the full (untruncated)
  convolution, i.e. the attacker sees every pixel the plate's light reaches and knows the rest of
  the scene. The rate times w h misses what leaks across the plate's border through the blur, which
  matters most for small plates, so B uses the block form wherever it is affordable.

B = sum_c I_c bits. Fano's inequality turns B into a ceiling on any attacker's exact-read rate for
plates drawn uniformly from a format with H bits of entropy: P(correct) <= (B + 1) / H.
"""

from __future__ import annotations

import logging
import math
from dataclasses import dataclass

import numpy as np
import torch
from tqdm.auto import tqdm

log = logging.getLogger(__name__)

ASSUMPTIONS = (
    "Upper bound on the bits B any attacker can extract about a plate, under these assumptions: "
    "(1) shift-invariant optics, PSF of the optical axis; "
    "(2) sensor linearised: additive white Gaussian noise, independent across pixels, channels and frames, "
    "with the shot + read variance of the LEAST radiance the plate shows (per channel minimum over the sharp "
    "training plate crops; read noise alone when not measured), so that no plate pixel is less noisy than "
    "assumed; neglected: the information shot noise carries through its variance, a relative 1/(2 v) of the "
    "Fisher information at variance v electrons^2 (0.15 % on the plates' ink); "
    "(3) plate content is at most as informative as a Gaussian field with the power spectrum estimated from "
    "sharp training plate crops (mean removed; spectrum scaled with plate width as S_w(f) = w^2 D(w f)); "
    "(4) R, G, B bounded separately and summed, an upper bound because the channels' noises are independent; "
    "(5) the Bayer mosaic, full-well clipping, 10-bit quantization and demosaicking are left out: each only "
    "removes information, so leaving them out keeps B an upper bound; "
    "(6) plates of up to 2048 px (w <~ 98 px) and every certified width: exact block bound, the attacker "
    "sees every pixel of the untruncated blur and knows the rest of the scene; larger plates: the per-pixel "
    "rate of an infinite plate times w h, an approximation that ignores leakage across the plate border "
    "(1-15 % below the block bound at 128 px for the built-in lenses); "
    "(7) Fano: plates drawn uniformly from the format, P(exact read) <= (B + 1) / H_plate."
)

BLOCK_MAX_PIXELS = 2048  # w h above this (w >~ 98 px): the block form costs > 1 s per channel, the rate is used
RATE_GRID = 256  # frequency samples per axis for the rate integral


@dataclass(frozen=True)
class PlateSpectrum:
    """Power spectrum of plate content, in radiance^2 per (cycle per plate width)^2, per channel.

    table: (3, 2*ny+1, 2*nx+1) density D at nu_x = -nx..nx cycles per plate width and
    nu_y = (-ny..ny) * aspect cycles per plate width (rows follow the plate's height). Beyond the
    table D follows the fitted tail amplitude * |nu|^-exponent. mean_radiance (3,) is the mean
    plate radiance; min_radiance (3,) the least (the bound's noise level; None: not measured, 0 is
    used); aspect = plate width / height.
    """

    table: np.ndarray
    aspect: float
    tail_amplitude: tuple[float, float, float]
    tail_exponent: float
    mean_radiance: tuple[float, float, float]
    n_crops: int = 0
    min_radiance: tuple[float, float, float] | None = None

    def noise_radiance(self) -> tuple[float, float, float]:
        """The least radiance per channel the plate shows (its noise is the least): `min_radiance`,
        or 0 (read noise alone, always conservative) when it was not measured."""
        return self.min_radiance if self.min_radiance is not None else (0.0, 0.0, 0.0)

    def density(self, nu_y: torch.Tensor, nu_x: torch.Tensor) -> torch.Tensor:
        """D at frequencies (cycles per plate width), shape (3, *nu_x.shape), float64."""
        table = torch.as_tensor(self.table, dtype=torch.float64)
        ny, nx = (table.shape[1] - 1) // 2, (table.shape[2] - 1) // 2
        ky, kx = nu_y / self.aspect + ny, nu_x + nx  # fractional table indices
        inside = (ky >= 0) & (ky <= 2 * ny) & (kx >= 0) & (kx <= 2 * nx)
        y0 = ky.clamp(0, 2 * ny - 1).floor().long()
        x0 = kx.clamp(0, 2 * nx - 1).floor().long()
        ty, tx = (ky - y0).clamp(0, 1), (kx - x0).clamp(0, 1)
        inner = ((1 - ty) * (1 - tx) * table[:, y0, x0] + (1 - ty) * tx * table[:, y0, x0 + 1]
                 + ty * (1 - tx) * table[:, y0 + 1, x0] + ty * tx * table[:, y0 + 1, x0 + 1])
        radius = torch.sqrt(nu_y**2 + nu_x**2).clamp(min=1.0)
        tail = torch.tensor(self.tail_amplitude, dtype=torch.float64).reshape(3, *[1] * nu_x.ndim) \
            * radius ** (-self.tail_exponent)
        return torch.where(inside, inner, tail)

    def pixel_density(self, width_px: float, size: int) -> torch.Tensor:
        """S_w(f) = w^2 D(w f) on the size x size DFT grid (fftfreq order), (3, size, size), radiance^2.

        `density` on the grid, evaluated separably (the table's bilinear interpolation on a grid is
        W_y @ table @ W_x^T): 3-5x faster at size 1024, equal to `density` within rounding.
        """
        nu = width_px * torch.fft.fftfreq(size, dtype=torch.float64)
        table = torch.as_tensor(self.table, dtype=torch.float64)
        ny, nx = (table.shape[1] - 1) // 2, (table.shape[2] - 1) // 2
        ky, kx = nu / self.aspect + ny, nu + nx  # fractional table indices of the rows and columns
        inner = _bilinear_weights(ky, 2 * ny + 1) @ table @ _bilinear_weights(kx, 2 * nx + 1).T
        inside = ((ky >= 0) & (ky <= 2 * ny))[:, None] & ((kx >= 0) & (kx <= 2 * nx))[None, :]
        radius = torch.sqrt(nu[:, None] ** 2 + nu[None, :] ** 2).clamp(min=1.0)
        tail = torch.tensor(self.tail_amplitude, dtype=torch.float64).reshape(3, 1, 1) * radius ** (-self.tail_exponent)
        return width_px**2 * torch.where(inside, inner, tail)

    def variance(self) -> np.ndarray:
        """Per-channel content variance inside the table's band (radiance^2), (3,)."""
        return self.table.sum(axis=(1, 2)) * self.aspect


def _bilinear_weights(k: torch.Tensor, n_bins: int) -> torch.Tensor:
    """(len(k), n_bins) weights of linear interpolation at fractional indices k, clamped as in `density`."""
    k0 = k.clamp(0, n_bins - 2).floor().long()
    t = (k - k0).clamp(0, 1)
    rows = torch.arange(len(k))
    weights = torch.zeros(len(k), n_bins, dtype=torch.float64)
    weights[rows, k0] = 1 - t
    weights[rows, k0 + 1] += t
    return weights


def plate_height_px(width_px: int, aspect: float) -> int:
    """Plate height in whole pixels for a plate `width_px` wide (at least 1)."""
    return max(1, round(width_px / aspect))


def noise_to_signal(lens: torch.nn.Module, radiance: tuple[float, ...] | torch.Tensor, frames: int = 1) -> torch.Tensor:
    """Noise variance over squared gain at radiance `radiance` (the bound uses the least plate radiance), (3,) float64, radiance^2 units.

    (e_c L_c + read^2) / (e_c^2 T): shot + read variance in electrons over the squared electrons per
    unit radiance, for T frames averaged. Equivalent to (mu_c + read^2) / full_well^2 / g_c^2 in
    normalised sensor units.
    """
    if frames < 1:
        raise ValueError(f"frames must be >= 1, got {frames}")
    e = lens.sensor.electrons_per_unit().to("cpu", torch.float64)  # the bound's arithmetic runs on the CPU
    level = torch.as_tensor(radiance, dtype=torch.float64)
    if level.shape != (3,) or bool((level < 0).any()):
        raise ValueError(f"operating radiance must be 3 non-negative values (R, G, B), got {level.tolist()}")
    return (e * level + lens.spec.sensor.read_noise_e**2) / (e**2 * frames)


def otf_power(psf: torch.Tensor, size: int) -> torch.Tensor:
    """|H(f)|^2 of a (3,K,K) PSF on the size x size DFT grid (fftfreq order), float64, |H(0)|^2 = 1 for unit sum."""
    if size < psf.shape[-1]:
        raise ValueError(f"frequency grid {size} must be at least the PSF size {psf.shape[-1]}")
    h = torch.fft.fft2(psf.to(torch.float64), s=(size, size))
    return h.real**2 + h.imag**2


def bits_per_pixel(psf: torch.Tensor, spectrum: PlateSpectrum, width_px: float, nsr: torch.Tensor,
                   grid: int = RATE_GRID) -> torch.Tensor:
    """Rate I_c (bits per pixel, (3,)) of an infinitely large plate at width scale `width_px`.

    Mean over a grid x grid sampling of the Nyquist square of 1/2 log2(1 + |H_c|^2 S_w,c / nsr_c).
    """
    snr = otf_power(psf, max(grid, psf.shape[-1])) * spectrum.pixel_density(width_px, max(grid, psf.shape[-1]))
    return 0.5 * torch.log2(1 + snr / nsr[:, None, None]).mean(dim=(1, 2))


def _lag_matrix(table: torch.Tensor, height: int, width: int) -> torch.Tensor:
    """(C, n, n) matrix M[p, q] = table[:, (y_p - y_q) mod P, (x_p - x_q) mod Q] over an height x width block."""
    yy, xx = torch.meshgrid(torch.arange(height), torch.arange(width), indexing="ij")
    yy, xx = yy.reshape(-1), xx.reshape(-1)
    dy = (yy[:, None] - yy[None, :]) % table.shape[-2]
    dx = (xx[:, None] - xx[None, :]) % table.shape[-1]
    return table[:, dy, dx]


def _covariance_lags(spectrum: PlateSpectrum, width_px: int, height_px: int) -> torch.Tensor:
    """Content covariance at every lag (3, S, S) (lag d at [d_y mod S, d_x mod S]): inverse DFT of S_w on a
    grid S >= 4 max(w, h), fine enough that the block's lags do not wrap."""
    size = 1 << max(6, math.ceil(math.log2(4 * max(width_px, height_px))))
    return torch.fft.ifft2(spectrum.pixel_density(width_px, size)).real


def _autocorrelation_lags(psf: torch.Tensor, width_px: int, height_px: int) -> torch.Tensor:
    """PSF autocorrelation at every lag (3, S, S), S = K + max(w, h): no wrap between its nonzero lags
    (|d| < K) and the block's."""
    size = psf.shape[-1] + max(width_px, height_px)
    h = torch.fft.rfft2(psf.to(torch.float64), s=(size, size))
    return torch.fft.irfft2(h.real**2 + h.imag**2, s=(size, size))


def _content_covariance(spectrum: PlateSpectrum, width_px: int, height_px: int) -> torch.Tensor:
    """Covariance of plate content over the w x h block, (3, n, n): inverse DFT of S_w on a fine grid."""
    return _lag_matrix(_covariance_lags(spectrum, width_px, height_px), height_px, width_px)


def _psf_gram(psf: torch.Tensor, width_px: int, height_px: int) -> torch.Tensor:
    """Gram matrix H^T H of the full convolution over a w x h block: the PSF autocorrelation at each lag."""
    return _lag_matrix(_autocorrelation_lags(psf, width_px, height_px), height_px, width_px)


def plate_bits_per_channel(psf: torch.Tensor, spectrum: PlateSpectrum, width_px: int, nsr: torch.Tensor,
                           method: str = "auto") -> torch.Tensor:
    """Bits (3,) leaked per channel about a plate `width_px` wide (height from the spectrum's aspect).

    method: "block" (exact for the w x h plate, see the module docstring), "rate" (w h times
    `bits_per_pixel`), or "auto" (block up to BLOCK_MAX_PIXELS pixels, else rate). Differentiable in
    the PSF.
    """
    height = plate_height_px(width_px, spectrum.aspect)
    if method == "auto":
        method = "block" if width_px * height <= BLOCK_MAX_PIXELS else "rate"
    if method == "rate":
        return width_px * height * bits_per_pixel(psf, spectrum, width_px, nsr)
    if method != "block":
        raise ValueError(f"method must be 'block', 'rate' or 'auto', got {method!r}")
    sigma = _content_covariance(spectrum, width_px, height)
    gram = _psf_gram(psf, width_px, height)
    eye = torch.eye(sigma.shape[-1], dtype=torch.float64)
    system = eye + sigma @ gram / nsr[:, None, None]
    # One channel at a time: torch 2.14's batched CPU LU (MKL) fails ("Parameter 6 was incorrect on
    # entry to DLASWP") and hangs on (3, n, n) batches with n ~ 900 and 2 threads.
    logdet = torch.stack([torch.linalg.slogdet(system[c])[1] for c in range(system.shape[0])])
    return logdet / (2 * math.log(2))


def plate_bits(psf: torch.Tensor, spectrum: PlateSpectrum, width_px: int, nsr: torch.Tensor,
               method: str = "auto") -> torch.Tensor:
    """B: bits leaked about a plate `width_px` wide, summed over R, G, B (scalar tensor)."""
    return plate_bits_per_channel(psf, spectrum, width_px, nsr, method).sum()


def fano_ceiling(bits: float | torch.Tensor, entropy_bits: float) -> float | torch.Tensor:
    """Ceiling on P(exact read) for plates uniform over a format of `entropy_bits`: min(1, (B + 1) / H)."""
    if entropy_bits <= 0:
        raise ValueError(f"plate entropy must be > 0 bits, got {entropy_bits}")
    ceiling = (bits + 1.0) / entropy_bits
    return ceiling.clamp(max=1.0) if isinstance(ceiling, torch.Tensor) else min(1.0, ceiling)


def trace_bound_bits_per_channel(psf: torch.Tensor, spectrum: PlateSpectrum, width_px: int,
                                 nsr: torch.Tensor, trace: torch.Tensor | None = None) -> torch.Tensor:
    """An upper bound (3,) on the block bits of `plate_bits_per_channel`, in O(w h) memory and time.

    The eigenvalues of A = Sigma G / nsr (both factors symmetric positive semi-definite) are real and
    non-negative, and log is concave, so 1/2 log2 det(I + A) = 1/2 sum_i log2(1 + lambda_i)
    <= n/2 log2(1 + tr(A) / n) (Jensen), n = w h. `trace`: tr(Sigma G) of `sigma_gram_trace` when
    already known (it does not depend on the noise).
    """
    n = width_px * plate_height_px(width_px, spectrum.aspect)
    if trace is None:
        trace = sigma_gram_trace(psf, spectrum, width_px)
    return n / 2 * torch.log2(1 + trace / nsr / n)


def sigma_gram_trace(psf: torch.Tensor, spectrum: PlateSpectrum, width_px: int) -> torch.Tensor:
    """tr(Sigma G) (3,) of the block bound at plate width `width_px`, without its n x n matrices: the sum
    over lags d of (h - |d_y|)(w - |d_x|) cov(d) autocorrelation(-d), radiance^2."""
    height = plate_height_px(width_px, spectrum.aspect)
    cov = _covariance_lags(spectrum, width_px, height)
    autocorrelation = _autocorrelation_lags(psf, width_px, height)
    dy, dx = torch.arange(1 - height, height), torch.arange(1 - width_px, width_px)
    pairs = (height - dy.abs()).to(torch.float64)[:, None] * (width_px - dx.abs()).to(torch.float64)[None, :]
    c = cov[:, dy[:, None] % cov.shape[-2], dx[None, :] % cov.shape[-1]]
    a = autocorrelation[:, (-dy[:, None]) % autocorrelation.shape[-2], (-dx[None, :]) % autocorrelation.shape[-1]]
    return (pairs * c * a).sum(dim=(1, 2))


@dataclass(frozen=True)
class WidthCertificate:
    """How `certify_width` found W_eps.

    width: W_eps (px). exact_widths: the widths whose exact block bound was computed (their n x n
    matrices built); trace_widths: those certified by the trace bound alone. limited_at: the first
    width neither bound could decide (the trace bound fails, the block would exceed
    `CERTIFY_MAX_PIXELS`; `width` is then only a lower bound on W_eps), None when the search ended on
    its own.
    """

    width: int
    exact_widths: tuple[int, ...]
    trace_widths: tuple[int, ...]
    limited_at: int | None = None

    def note(self, aspect: float) -> str | None:
        """A sentence for the row when the width is only a lower bound, else None."""
        if self.limited_at is None:
            return None
        n = self.limited_at * plate_height_px(self.limited_at, aspect)
        return (f"W_eps >= {self.width} px, a lower bound: at {self.limited_at} px the trace bound does not "
                f"certify and the exact block bound would need {n} x {n} matrices (cap {CERTIFY_MAX_PIXELS} px)")


# The exact block bound in the W_eps search is built up to this many plate pixels: its n x n matrices
# take ~0.5 GB at n = 2048 and its time grows as n^3 (seconds already at n ~ 1400 on 2 cores,
# docs/history.md); beyond it only the trace bound may certify.
CERTIFY_MAX_PIXELS = BLOCK_MAX_PIXELS
# A width is certified by the trace bound only with this relative margin, so that the rounding of
# the two computations never certifies a width the exact bound alone would refuse.
_TRACE_MARGIN = 1e-9


def certify_width(psf: torch.Tensor, spectrum: PlateSpectrum, nsr: torch.Tensor, entropy_bits: float,
                  eps: float = 0.05, max_width_px: int = 256,
                  traces: dict[int, torch.Tensor] | None = None) -> WidthCertificate:
    """W_eps with how it was found; see `certified_width`.

    Widths are searched one pixel at a time, stopping at the first failure. Each width is first
    tried with the cheap trace bound (`trace_bound_bits_per_channel`, never below the block bound):
    when that already puts the ceiling at or below eps, the width is certified without building the
    block's matrices, which is what keeps a very dark lens (tiny bits at every width, so the search
    runs to `max_width_px`, where n ~ 14 000) from needing hours and gigabytes. Otherwise the exact
    block bound decides, as before, while n <= CERTIFY_MAX_PIXELS; beyond that the search stops and
    says so (`limited_at`). The width found equals that of the exact search wherever the exact
    search stays within the cap. `traces` (width -> `sigma_gram_trace`) is filled and reused: the
    searches of one lens for several frame counts share it.
    """
    traces = {} if traces is None else traces
    width = 0
    exact: list[int] = []  # widths decided by the block bound
    trace: list[int] = []  # widths certified by the trace bound
    with torch.no_grad(), tqdm(total=max_width_px, desc="certified plate width", unit="px", leave=False,
                               delay=2.0) as bar:
        while width < max_width_px:
            w = width + 1
            if w not in traces:
                traces[w] = sigma_gram_trace(psf, spectrum, w)
            upper = float(trace_bound_bits_per_channel(psf, spectrum, w, nsr, traces[w]).sum())
            if fano_ceiling(upper * (1 + _TRACE_MARGIN), entropy_bits) <= eps:
                trace.append(w)
            elif w * plate_height_px(w, spectrum.aspect) > CERTIFY_MAX_PIXELS:
                return WidthCertificate(width, tuple(exact), tuple(trace), limited_at=w)
            else:
                exact.append(w)
                bits = float(plate_bits(psf, spectrum, w, nsr, method="block"))
                if fano_ceiling(bits, entropy_bits) > eps:
                    break
            width = w
            bar.update(1)
    return WidthCertificate(width, tuple(exact), tuple(trace))


def certified_width(psf: torch.Tensor, spectrum: PlateSpectrum, nsr: torch.Tensor, entropy_bits: float,
                    eps: float = 0.05, max_width_px: int = 256) -> int:
    """W_eps: the largest plate width (px) such that the ceiling is <= eps at every width up to it.

    0 when even a 1 px plate is not certified (e.g. eps * H < 1: Fano cannot certify below 1/H).
    A lens certified up to `max_width_px` returns `max_width_px`. See `certify_width` for the search
    (and for the lower bound it returns when a width needs too large an exact block).
    """
    return certify_width(psf, spectrum, nsr, entropy_bits, eps, max_width_px).width


def bound_curve(lens: torch.nn.Module, spectrum: PlateSpectrum, widths_px: list[int] | np.ndarray,
                entropy_bits: float, frames: int = 1) -> dict[str, np.ndarray]:
    """B and the Fano ceiling per plate width, for the chart: {"width_px", "bits", "ceiling"} arrays."""
    nsr = noise_to_signal(lens, spectrum.noise_radiance(), frames)
    with torch.no_grad():
        psf = lens.psf().cpu()  # float64 matrices of plate size: CPU work on any lens device
        bits = np.array([float(plate_bits(psf, spectrum, int(w), nsr)) for w in widths_px])
    return {"width_px": np.asarray(widths_px, dtype=int), "bits": bits,
            "ceiling": np.minimum(1.0, (bits + 1.0) / entropy_bits)}


def bound_row(lens: torch.nn.Module, spectrum: PlateSpectrum, entropy_bits: float,
              widths_px: tuple[int, ...] = (16, 32, 64, 128), eps: float = 0.05,
              frames: tuple[int, ...] = (1, 30)) -> dict[str, float | int | str]:
    """Flat metrics of the bound for one lens (the runner's `bound` row).

    Keys: bound_entropy_bits, bound_eps, bound_radiance_{r,g,b} (mean plate radiance),
    bound_noise_radiance_{r,g,b} (the least plate radiance, where the noise is set), and per T in
    `frames`: bound_bits_w{W}_t{T}, bound_ceiling_w{W}_t{T} for each width and bound_width_eps_t{T}
    (W_eps in px), and bound_width_eps_note_t{T} where that W_eps is only a lower bound (see
    `certify_width`); bound_assumptions carries ASSUMPTIONS.
    """
    row: dict[str, float | int | str] = {"bound_entropy_bits": float(entropy_bits), "bound_eps": float(eps)}
    row.update({f"bound_radiance_{c}": float(v) for c, v in zip("rgb", spectrum.mean_radiance)})
    row.update({f"bound_noise_radiance_{c}": float(v) for c, v in zip("rgb", spectrum.noise_radiance())})
    traces: dict[int, torch.Tensor] = {}  # tr(Sigma G) per width, shared by the W_eps search of every T
    with torch.no_grad():
        psf = lens.psf().cpu()  # float64 matrices of plate size: CPU work on any lens device
        for t in frames:
            nsr = noise_to_signal(lens, spectrum.noise_radiance(), t)
            for w in widths_px:
                bits = float(plate_bits(psf, spectrum, w, nsr))
                row[f"bound_bits_w{w}_t{t}"] = bits
                row[f"bound_ceiling_w{w}_t{t}"] = float(fano_ceiling(bits, entropy_bits))
            certificate = certify_width(psf, spectrum, nsr, entropy_bits, eps, traces=traces)
            row[f"bound_width_eps_t{t}"] = certificate.width
            note = certificate.note(spectrum.aspect)
            if note is not None:
                log.warning("%s (T = %d frames)", note, t)
                row[f"bound_width_eps_note_t{t}"] = note
    row["bound_assumptions"] = ASSUMPTIONS
    return row
