"""Lens simulation: phase mask or measured PSF, Fourier-optics PSF, sensor model, lens specs and registry.

The phase mask (``zernike``, or a height map read by ``height_file``; its glass in ``materials``), the
PSF on the sensor grid (``optics``; a measured one read and resampled by ``measured``), image formation
(``convolve``) and the sensor (``sensor``) make a camera (``lens``); a camera is a spec (``spec``, the
built-in ones in ``specs/`` and ``builtin``, examples of every kind in ``specs/examples/``), registered
here by name. Beside them: the
mask as a fab's height map (``mask_export``), object distance from pixel size (``depth``), and the
attack-independent privacy bound (``bound``) and the sensor's raw electrons as the ideal observer's
likelihood (``raw_likelihood``).

    lens = lenses.load("ideal")          # built-in / entry-point name, or a path to a .toml spec
    psf = lens.psf()                     # (3, K, K), each channel sums to 1
    y = lens(x, generator=g)             # (B,3,H,W) scene in [0,1] -> sensor image in [0,1]
"""

from __future__ import annotations

from pathlib import Path
from typing import Any

from lenses.lens import Lens
from common.plugins import DuplicateNameError, discover, suggest
from lenses.spec import LensSpec, LensSpecError, load_spec, parse_spec, spec_to_toml
from lenses.zernike import zernike_basis

GROUP = "privacy_lens_bench.lenses"

__all__ = ["GROUP", "Lens", "LensSpec", "LensSpecError", "UnknownLensError", "available", "load", "load_spec",
           "parse_spec", "spec_to_toml", "zernike_basis", "DuplicateNameError"]


class UnknownLensError(LookupError):
    """No registered lens and no spec file has this name."""


def available() -> dict[str, str]:
    """Registered lens names -> "module:attr", without importing any of them."""
    return {name: ep.value for name, ep in sorted(discover(GROUP).items())}


def load(name: str | Path, **options: Any) -> Lens:
    """A lens by registered name (built-in or any installed plugin) or by path to a .toml spec.

    `options` (e.g. profile, seed, device, cache_dir) reach the factory of a registered lens;
    fixed lenses ignore them.
    """
    text = str(name)
    if text.endswith(".toml") or Path(text).is_file():
        return Lens(load_spec(text))
    entries = discover(GROUP)
    if text not in entries:
        raise UnknownLensError(
            f"unknown lens {text!r}.{suggest(text, entries)} Registered lenses: {', '.join(sorted(entries))}; "
            "or pass the path of a .toml lens spec"
        )
    lens = entries[text].load()(**options)
    if not isinstance(lens, Lens):
        raise TypeError(f"lens plugin {text!r} ({entries[text].value}) returned {type(lens).__name__}, not a Lens")
    return lens
