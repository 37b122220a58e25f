"""Built-in fixed lenses, registered through the `privacy_lens_bench.lenses` entry-point group."""

from __future__ import annotations

from pathlib import Path

import torch

from lenses.lens import Lens
from lenses.optics import Geometry, pupil_samples_for
from lenses.spec import LensSpec, load_spec

SPEC_DIR = Path(__file__).parent / "specs"
# One shipped example spec per kind of encoder (lenses.spec.KINDS), for `--lens FILE.toml`.
EXAMPLES = {"zernike": SPEC_DIR / "examples" / "zernike-15.toml",
            "measured-psf": SPEC_DIR / "examples" / "measured-defocus.toml",
            "height-map": SPEC_DIR / "examples" / "gp-height-map.toml"}


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


class SensorOnlyLens(Lens):
    """A perfect lens in front of the suite's sensor: the PSF is a delta (K = 1), so the sensor
    image is the sensor model (tint, RGGB mosaic, noise, quantization, demosaic) applied to
    the sharp scene itself. A reference: whatever privacy it shows is the sensor's, not a lens's.
    """

    def __init__(self, spec: LensSpec):
        # A 1-pixel support keeps the (unused) pupil model tiny; the PSF below does not use it.
        super().__init__(spec, Geometry(pupil_samples_for(spec, 1), 1))
        self.initial_energy_fraction = torch.ones(3)

    def psf_and_energy(self) -> tuple[torch.Tensor, torch.Tensor]:
        """Delta PSF (3, 1, 1) of ones and energy fraction (3,) of ones (nothing is lost)."""
        ones = torch.ones(3, 1, 1, dtype=torch.float32, device=self.coefficients_um.device)
        return ones, ones.reshape(3)


def sensor_only(**_: object) -> Lens:
    """No blur: only the sensor's tint, mosaic, noise and quantization (a reference lens)."""
    return SensorOnlyLens(load_spec(SPEC_DIR / "sensor-only.toml"))
