"""Where the mask starts and whether it ended on its bounds.

Start: a seeded small random draw, not exactly zero. At c = 0 the defocus and astigmatism terms
(Z4-Z6) sit on a stationary point of every loss (the PSF width is even in each of them; their
gradients measure about 1e-20), so the first direction would be picked by rounding noise. A draw
of at most INITIAL_AMPLITUDE_UM = 0.05 um of glass per term (0.04 waves of optical path at 550 nm
in fused silica; a Strehl ratio of 0.8 or more even when Z4-Z6 all draw the maximum, so the
starting lens is still sharp) is larger than one Adam step of the quick profile (0.02 um), so the
seed, not rounding, decides where the optics go first.
"""

from __future__ import annotations

import numpy as np

from lenses.spec import LensSpec

INITIAL_AMPLITUDE_UM = 0.05
# A coefficient within this fraction of its bound range of a bound ended there (the optimiser
# projects onto the bound, so a bound-limited coefficient sits on it or one step inside).
BOUND_TOLERANCE = 0.01
NOLL_NAMES = ("Z1 piston", "Z2 tilt x", "Z3 tilt y", "Z4 defocus", "Z5 astigmatism 45", "Z6 astigmatism 0")


def noll_name(j: int) -> str:
    """A label for Noll term j >= 1: its name for Z1..Z6, "Zj" beyond (a mask of more terms)."""
    return NOLL_NAMES[j - 1] if j <= len(NOLL_NAMES) else f"Z{j}"


def initial_coefficients(spec: LensSpec, seed: int, amplitude_um: float = INITIAL_AMPLITUDE_UM) -> tuple[float, ...]:
    """Starting coefficients (um): the spec's plus a uniform draw in [-amplitude_um, amplitude_um]
    on every term its bounds leave free, clipped to the bounds; a pure function of `seed`."""
    if spec.mask.bounds_um is None:
        raise ValueError(f"lens spec {spec.name!r} declares no mask.bounds_um: nothing is trained, nothing to draw")
    rng = np.random.default_rng([seed, 0xC0EF])  # its own stream: not random-zernike's draw for this seed
    draw = rng.uniform(-amplitude_um, amplitude_um, len(spec.mask.zernike_um))
    out = []
    for c, d, (lo, hi) in zip(spec.mask.zernike_um, draw, spec.mask.bounds_um):
        out.append(float(np.clip(c + d, lo, hi)) if hi > lo else float(c))
    return tuple(out)


def bound_limited(coefficients_um: list[float], bounds_um: tuple[tuple[float, float], ...],
                  tolerance: float = BOUND_TOLERANCE) -> list[int]:
    """Noll indices j (1-based) of the free coefficients within `tolerance` x (hi - lo) of a bound."""
    limited = []
    for j, (c, (lo, hi)) in enumerate(zip(coefficients_um, bounds_um), start=1):
        if hi > lo and min(c - lo, hi - c) <= tolerance * (hi - lo):
            limited.append(j)
    return limited
