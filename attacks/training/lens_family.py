"""The family of lenses the registry's lenses come from, to draw training lenses from.

Every co-designed lens of the registry is a 6-term Zernike mask inside the co-design bounds of
``lenses/specs/codesign.toml`` (Z2, Z3 within +-0.5 um, Z4-Z6 within +-1 um of glass, in front of
the F/5 lens focused on the street); the fixed ``ideal`` lens is its centre and ``defocus`` the same
lens focused at 2 m instead of 10 m. A draw is, with probability ``MASK_SHARE``, a mask whose
coefficients are drawn independently, each at one of its two bounds (equally likely) with probability
``AT_BOUND`` and otherwise uniform between them (piston, frozen by the bounds, stays 0); else a lens
without a mask focused at a distance uniform in dioptres between the street (10 m, in focus) and 2 m
(the ``defocus`` lens). Co-design drives the masks to the bounds (the published co-designed lenses
sit at vertices of the box, or on an edge), so the draw gives the faces, edges and vertices of the
box their weight: 0.6^5 = 7.8 % of mask draws are vertices. A co-designed lens may therefore coincide
with a drawn one (a lens-access attacker may simulate its own lens anyway); the held-out lenses of the
pre-training are drawn apart. ``random-zernike`` (Z2, Z3 up to +-1 um) lies outside the family and is a
lens it can be tested on without having been drawn.

Near-sharp lenses (``sharp_share``, 0 by default): with that probability, decided by one more number
drawn after the others (so a family without them draws exactly as before), a draw is instead a mask
whose tilts (Z2, Z3: they only shift the image) are uniform inside their bounds and whose aberrations
(Z4-Z6) are uniform within ``SHARP_FRACTION`` of theirs: the regime of the sharp lenses (``ideal`` is the
centre; the co-designed ``os`` lens has Z4-Z6 within 0.11 um), which the draws above reach rarely.

A draw is a function of its ``torch.Generator`` only; ``describe`` is the family's identity in a
cache key.
"""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass
from typing import Any

import torch

from lenses.lens import Lens
from lenses.spec import LensSpec, load_spec
from lenses.builtin import SPEC_DIR

__all__ = ["AT_BOUND", "DEFOCUS_RANGE_M", "MASK_SHARE", "SHARP_FRACTION", "FamilyLens", "LensFamily"]

MASK_SHARE = 0.75
"""Share of draws that are co-design masks; the rest are out-of-focus lenses."""

AT_BOUND = 0.6
"""Probability that a mask coefficient is drawn at one of its bounds rather than between them."""

DEFOCUS_RANGE_M = (2.0, 10.0)
"""Focus distances of the out-of-focus draws (nearest, farthest = in focus), uniform in dioptres."""

SHARP_FRACTION = 0.2
"""A near-sharp draw's aberrations (Z4-Z6) lie within this fraction of their bounds."""

TILT_TERMS = 3
"""Piston, Z2 and Z3: the terms that only shift the image (a near-sharp draw keeps them whole)."""


@dataclass(frozen=True)
class FamilyLens:
    """One drawn lens: ``kind`` "mask" (its ``zernike_um``) or "defocus" (its ``focus_distance_m``)."""

    kind: str
    zernike_um: tuple[float, ...]
    focus_distance_m: float

    def describe(self) -> dict[str, Any]:
        return {"kind": self.kind, "zernike_um": [round(c, 6) for c in self.zernike_um],
                "focus_distance_m": round(self.focus_distance_m, 6)}


class LensFamily:
    """Draws lenses of the family (module docs) and builds them.

    ``sharp_share``: the probability of a near-sharp draw (module docs); 0 draws as the family always has.
    The mask draws share one ``Lens`` whose coefficients are set per draw (its grids are sized for
    the whole bounds box, so every draw fits); an out-of-focus draw builds its own ``Lens``.
    """

    def __init__(self, sharp_share: float = 0.0) -> None:
        if not 0.0 <= sharp_share <= 1.0:
            raise ValueError(f"LensFamily sharp_share must be in [0, 1], got {sharp_share!r}")
        self.sharp_share = float(sharp_share)
        self.mask_spec: LensSpec = load_spec(SPEC_DIR / "codesign.toml")
        self.defocus_spec: LensSpec = load_spec(SPEC_DIR / "defocus.toml")
        bounds = self.mask_spec.mask.bounds_um
        if bounds is None:
            raise ValueError("lenses/specs/codesign.toml declares no mask bounds; the lens family needs them")
        self.bounds_um: tuple[tuple[float, float], ...] = bounds
        self._mask_lens: Lens | None = None

    def draw(self, generator: torch.Generator, sharp: bool | None = None) -> FamilyLens:
        """One lens of the family, from ``generator`` alone; ``sharp`` True or False forces the near-sharp
        branch or the others (None: with probability ``sharp_share``)."""
        n = len(self.bounds_um)
        u = torch.rand(1 + 3 * n, generator=generator, dtype=torch.float64).tolist()
        street = self.defocus_spec.optics.object_distance_m
        if sharp is None and self.sharp_share > 0.0:
            sharp = float(torch.rand(1, generator=generator, dtype=torch.float64)) < self.sharp_share
        if sharp:
            coefficients = tuple(lo + (hi - lo) * t if i < TILT_TERMS else
                                 SHARP_FRACTION * (lo + (hi - lo) * t)
                                 for i, ((lo, hi), t) in enumerate(zip(self.bounds_um, u[1 + 2 * n:])))
            return FamilyLens("mask", coefficients, street)
        if u[0] < MASK_SHARE:
            coefficients = tuple((lo if end < 0.5 else hi) if at < AT_BOUND else lo + (hi - lo) * t
                                 for (lo, hi), at, end, t in zip(self.bounds_um, u[1:1 + n], u[1 + n:1 + 2 * n],
                                                                  u[1 + 2 * n:]))
            return FamilyLens("mask", coefficients, street)
        near, far = DEFOCUS_RANGE_M
        dioptres = 1.0 / far + u[1] * (1.0 / near - 1.0 / far)
        return FamilyLens("defocus", (0.0,) * len(self.bounds_um), 1.0 / dioptres)

    def build(self, drawn: FamilyLens) -> Lens:
        """The ``Lens`` of a draw (the shared mask lens is updated in place for a mask draw)."""
        if drawn.kind == "mask":
            if self._mask_lens is None:
                self._mask_lens = Lens(self.mask_spec)
            with torch.no_grad():
                self._mask_lens.coefficients_um.copy_(torch.tensor(drawn.zernike_um, dtype=torch.float32))
            return self._mask_lens
        optics = dataclasses.replace(self.defocus_spec.optics, focus_distance_m=drawn.focus_distance_m)
        return Lens(dataclasses.replace(self.defocus_spec, optics=optics,
                                        name=f"defocus-{drawn.focus_distance_m:.2f}m"))

    def describe(self) -> dict[str, Any]:
        """The family's identity (for cache keys and provenance)."""
        sharp = {"sharp_share": self.sharp_share, "sharp_fraction": SHARP_FRACTION} if self.sharp_share else {}
        return {**sharp, "mask_share": MASK_SHARE, "at_bound": AT_BOUND, "bounds_um": [list(b) for b in self.bounds_um],
                "mask_spec": self.mask_spec.to_dict(), "defocus_range_m": list(DEFOCUS_RANGE_M),
                "defocus_spec": self.defocus_spec.to_dict()}
