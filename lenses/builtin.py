"""Built-in fixed lenses, registered through the `privacy_lens_bench.lenses` entry-point group."""

from __future__ import annotations

from pathlib import Path

from lenses.lens import Lens
from lenses.spec import load_spec

SPEC_DIR = Path(__file__).parent / "specs"


def _fixed(name: str) -> Lens:
    return Lens(load_spec(SPEC_DIR / f"{name}.toml"))


def ideal(**_: object) -> Lens:
    """In focus at the object plane, no mask: the diffraction-limited F/5 reference."""
    return _fixed("ideal")


def defocus(**_: object) -> Lens:
    """Focused at 2 m while the street is at 10 m: a visibly blurring out-of-focus lens."""
    return _fixed("defocus")


def random_zernike(**_: object) -> Lens:
    """A seeded random 6-term Zernike mask."""
    return _fixed("random-zernike")
