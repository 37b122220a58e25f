"""Refractive indices of mask materials."""

from __future__ import annotations

import math

# Malitson (1965), "Interspecimen comparison of the refractive index of fused silica", lambda in um.
_FUSED_SILICA_B = (0.6961663, 0.4079426, 0.8974794)
_FUSED_SILICA_C_UM = (0.0684043, 0.1162414, 9.896161)


def fused_silica_index(wavelength_nm: float) -> float:
    """Refractive index of fused silica at a vacuum wavelength in nm (Sellmeier, Malitson 1965).

    Valid from 210 nm to 3710 nm; 550 nm gives 1.4599.
    """
    if not 210.0 <= wavelength_nm <= 3710.0:
        raise ValueError(f"wavelength_nm={wavelength_nm} is outside fused silica's Sellmeier range 210-3710 nm")
    lam2 = (wavelength_nm / 1000.0) ** 2
    n2 = 1.0 + sum(b * lam2 / (lam2 - c * c) for b, c in zip(_FUSED_SILICA_B, _FUSED_SILICA_C_UM))
    return math.sqrt(n2)


MATERIALS = {"fused-silica": fused_silica_index}


def refractive_index(material: str, wavelength_nm: float) -> float:
    """Refractive index of a named mask material at wavelength_nm."""
    try:
        return MATERIALS[material](wavelength_nm)
    except KeyError:
        raise ValueError(f"unknown mask material {material!r}; known: {sorted(MATERIALS)}") from None
