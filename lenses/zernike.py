"""Zernike polynomials in Noll order, RMS-normalised over the unit disk.

Noll (1976) ordering and normalisation: Z_1 = 1, Z_2 = 2 rho cos(theta), Z_3 = 2 rho sin(theta),
Z_4 = sqrt(3) (2 rho^2 - 1), Z_5 = sqrt(6) rho^2 sin(2 theta), Z_6 = sqrt(6) rho^2 cos(2 theta), ...
Each term has unit RMS over the disk, so a coefficient is directly the RMS of its term.
"""

from __future__ import annotations

import math
from functools import lru_cache

import numpy as np
import torch


def noll_to_nm(j: int) -> tuple[int, int]:
    """Radial order n and signed azimuthal frequency m of Noll index j >= 1.

    Even j carry cos(m theta) (m > 0), odd j carry sin(|m| theta) (m < 0); m = 0 is rotationally
    symmetric.
    """
    if j < 1:
        raise ValueError(f"Noll index must be >= 1, got {j}")
    n = 0
    while (n + 1) * (n + 2) // 2 < j:
        n += 1
    k = j - n * (n + 1) // 2 - 1  # position of j within radial order n, 0-based
    # The |m| values within order n run n%2, n%2, n%2+2, n%2+2, ... (m = 0 appears once).
    ms = []
    for m in range(n % 2, n + 1, 2):
        ms.extend([m] if m == 0 else [m, m])
    m = ms[k]
    if m != 0 and j % 2 == 1:
        m = -m
    return n, m


def radial(n: int, m: int, rho: np.ndarray) -> np.ndarray:
    """Zernike radial polynomial R_n^|m|(rho)."""
    m = abs(m)
    out = np.zeros_like(rho)
    for k in range((n - m) // 2 + 1):
        coef = (-1) ** k * math.factorial(n - k) / (
            math.factorial(k) * math.factorial((n + m) // 2 - k) * math.factorial((n - m) // 2 - k)
        )
        out = out + coef * rho ** (n - 2 * k)
    return out


def zernike_noll(j: int, rho: np.ndarray, theta: np.ndarray) -> np.ndarray:
    """RMS-normalised Noll Zernike term j evaluated at polar coordinates (rho <= 1)."""
    n, m = noll_to_nm(j)
    norm = math.sqrt(n + 1) if m == 0 else math.sqrt(2 * (n + 1))
    r = radial(n, m, rho)
    if m > 0:
        return norm * r * np.cos(m * theta)
    if m < 0:
        return norm * r * np.sin(-m * theta)
    return norm * r


def pupil_coordinates(n_samples: int) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Normalised pupil grid: (rho, theta, inside) of shape (n, n).

    Samples sit at pixel centres of an n x n grid spanning [-1, 1] in x (columns) and y (rows),
    so the grid spacing is 2 / n and the disk is sampled symmetrically.
    """
    c = (np.arange(n_samples) + 0.5) / n_samples * 2.0 - 1.0
    x, y = np.meshgrid(c, c, indexing="xy")
    rho = np.hypot(x, y)
    return rho, np.arctan2(y, x), rho <= 1.0


@lru_cache(maxsize=16)
def _basis_numpy(n_terms: int, n_samples: int) -> np.ndarray:
    rho, theta, inside = pupil_coordinates(n_samples)
    terms = [np.where(inside, zernike_noll(j, rho, theta), 0.0) for j in range(1, n_terms + 1)]
    basis = np.stack(terms).astype(np.float64)
    basis.setflags(write=False)
    return basis


def zernike_basis(n_terms: int, n_samples: int, dtype: torch.dtype = torch.float32,
                  device: torch.device | str = "cpu") -> torch.Tensor:
    """Noll-ordered, RMS-normalised Zernike basis on an n_samples x n_samples pupil grid.

    Returns a tensor (n_terms, n_samples, n_samples), zero outside the unit disk. The grid is
    cached per (n_terms, n_samples); a fresh tensor is returned each call.
    """
    if n_terms < 1 or n_samples < 2:
        raise ValueError(f"need n_terms >= 1 and n_samples >= 2, got {n_terms}, {n_samples}")
    return torch.as_tensor(_basis_numpy(n_terms, n_samples).copy(), dtype=dtype, device=device)


def max_gradient(j: int) -> float:
    """Largest |grad Z_j| over the closed unit disk (per unit of normalised radius).

    Evaluated in closed form: for Z = N R_n^m(rho) trig(m theta), |grad Z|^2 = N^2 (R'^2 trig^2 +
    (m R / rho)^2 trig'^2); its maximum over theta is N max(|R'|, |m R / rho|) at fixed rho, and
    for Zernike terms both are largest at the rim (checked over a fine radial grid).
    """
    n, m = noll_to_nm(j)
    norm = math.sqrt(n + 1) if m == 0 else math.sqrt(2 * (n + 1))
    rho = np.linspace(1e-6, 1.0, 4001)
    r = radial(n, m, rho)
    dr = np.gradient(r, rho)
    tangential = np.abs(m) * np.abs(r) / rho
    return float(norm * np.max(np.maximum(np.abs(dr), tangential)))
