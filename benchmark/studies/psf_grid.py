"""PSF grid study: how the PSF support K, the pupil grid N and the pixel integration trade
simulation error against the time of one PSF evaluation with its gradient.

For each lens the reference PSF uses a finer model than any choice studied (K 1.5 times the largest
K studied, twice the pupil samples that K needs, exact pixel integration); its measured energy
fraction is recorded. Each variant changes one knob from the suite's defaults (which integrate each
pixel exactly) and is scored by
- ``psf_l1``: sum over pixels of |PSF - reference| (reference kept at its own energy fraction,
  the variant embedded at the centre), averaged over the colour channels; 2 = disjoint, 0 = equal;
- ``image_psnr_db``: PSNR of a synthetic street scene blurred by the variant against the same
  scene blurred by the reference (what the attackers and the utility net actually see);
The pixel-integration knob (``oversample``) replaces the exact integral by the sum of the intensity
at the midpoints of s x s cells per pixel (the suite's rule before, with s = 3); value 0 is the exact
integral, the default.

- ``psf_grad_ms``: fastest of ``repeats`` timings of PSF + backward through the coefficients on one
  thread, in process CPU time (one thread, CPU time and the minimum, not wall time or the median:
  the figure least disturbed by other work on a shared machine, so that the knobs compare with each
  other; absolute times with more threads differ).
"""

from __future__ import annotations

import dataclasses
import json
import time
from pathlib import Path
from typing import Any

import torch

from benchmark.store.cache import atomic_write_text
from benchmark.results.metrics import psnr
from benchmark.store.provenance import provenance
from lenses.convolve import convolve
from lenses.optics import Geometry, PupilModel, choose_geometry, pupil_samples_for, worst_case_coefficients
from lenses.spec import LensSpec, load_spec

SPECS = Path(__file__).resolve().parent.parent.parent / "lenses" / "specs"
REFERENCE_MAX_PSF_PX = 301
ENERGY_FRACTIONS = (0.9, 0.95, 0.99, 0.995, 0.999)
PUPIL_SAMPLES = (64, 128, 256, 512)
OVERSAMPLES = (1, 2, 3, 4, 6)  # midpoint rules; 0 = the exact integral (default)


def study_lenses() -> dict[str, LensSpec]:
    """The fixed lenses, and the co-design start spec with every coefficient at its bound (the
    largest PSF a co-designed lens can reach), all as fixed masks."""
    specs = {name: load_spec(SPECS / f"{name}.toml") for name in ("ideal", "defocus", "random-zernike")}
    start = load_spec(SPECS / "codesign.toml")
    corner = tuple(float(c) for c in worst_case_coefficients(start))
    specs["codesign-at-bounds"] = dataclasses.replace(
        start, name="codesign-at-bounds", mask=dataclasses.replace(start.mask, zernike_um=corner, bounds_um=None))
    return specs


def _with_simulation(spec: LensSpec, **changes: Any) -> LensSpec:
    return dataclasses.replace(spec, simulation=dataclasses.replace(spec.simulation, **changes))


def _pixel_energy(model: PupilModel, coeffs: torch.Tensor, oversample: int) -> torch.Tensor:
    """(3, K, K) energy per pixel: exact (oversample 0) or summed over s x s midpoint samples."""
    if oversample == 0:
        return model.pixel_energy(coeffs)[0]
    k, s = model.geometry.psf_size_px, oversample
    samples = model.sampled_intensity(coeffs, s).reshape(3, k, s, k, s).sum(dim=(2, 4))
    return samples * (model.pitch_mm / s) ** 2


def _psf(spec: LensSpec, geometry: Geometry, oversample: int = 0) -> torch.Tensor:
    """PSF (3, K, K) float64, each channel at its true energy fraction (not renormalised)."""
    model = PupilModel(spec, geometry)
    coeffs = torch.tensor(spec.mask.zernike_um, dtype=torch.float64)
    with torch.no_grad():
        pixels, total = model.pixel_energy(coeffs)
        if oversample:
            pixels = _pixel_energy(model, coeffs, oversample)
    return pixels.double() / total[:, None, None]


def _psf_grad_ms(spec: LensSpec, geometry: Geometry, oversample: int, repeats: int) -> float:
    model = PupilModel(spec, geometry)
    coeffs = torch.tensor(spec.mask.zernike_um, dtype=torch.float32, requires_grad=True)
    weights = torch.rand(3, geometry.psf_size_px, geometry.psf_size_px, generator=torch.Generator().manual_seed(0))
    times, threads = [], torch.get_num_threads()
    torch.set_num_threads(1)
    try:
        for _ in range(repeats + 1):  # the first run warms the allocator up and is dropped
            t0 = time.process_time()
            pixels = _pixel_energy(model, coeffs, oversample)
            (pixels / pixels.sum(dim=(1, 2), keepdim=True) * weights).sum().backward()
            times.append(time.process_time() - t0)
    finally:
        torch.set_num_threads(threads)
    return 1e3 * min(times[1:])


def _embed(psf: torch.Tensor, size: int) -> torch.Tensor:
    k = psf.shape[-1]
    if k > size:
        lo = (k - size) // 2
        return psf[:, lo:lo + size, lo:lo + size]
    out = psf.new_zeros(3, size, size)
    lo = (size - k) // 2
    out[:, lo:lo + k, lo:lo + k] = psf
    return out


def variants(spec: LensSpec, default: Geometry) -> list[tuple[str, float, LensSpec, Geometry, int]]:
    """(knob, value, spec, geometry, oversample) for every variant: one knob moved from ``default``,
    the geometry the suite chooses for ``spec``; oversample 0 = exact pixel integration."""
    out = []
    for fraction in ENERGY_FRACTIONS:
        s = _with_simulation(spec, psf_energy_fraction=fraction, max_psf_size_px=REFERENCE_MAX_PSF_PX)
        out.append(("energy_fraction", fraction, s, choose_geometry(s)[0], 0))
    for n in PUPIL_SAMPLES:
        out.append(("pupil_samples", n, spec, dataclasses.replace(default, pupil_samples=n), 0))
    for s in (0, *OVERSAMPLES):
        out.append(("oversample", s, spec, default, s))
    return out


def measure(scene: torch.Tensor, repeats: int = 5, specs: dict[str, LensSpec] | None = None) -> list[dict]:
    """Records of every variant of every lens (see the module docstring). ``scene`` is (1, 3, H, W)."""
    records = []
    for name, spec in (specs or study_lenses()).items():
        default, _ = choose_geometry(spec)
        cases = variants(spec, default)
        ref_spec = _with_simulation(spec, max_pupil_samples=4096)
        ref_k = min(int(1.5 * max(g.psf_size_px for *_, g, _ in cases)) | 1, REFERENCE_MAX_PSF_PX)
        ref_geometry = Geometry(2 * pupil_samples_for(ref_spec, ref_k), ref_k)
        ref = _psf(ref_spec, ref_geometry)
        ref_image = convolve(scene.double(), ref)
        for knob, value, spec_v, geometry, oversample in cases:
            psf = _psf(spec_v, geometry, oversample)
            image = convolve(scene.double(), psf / psf.sum(dim=(1, 2), keepdim=True))
            records.append({
                "lens": name, "knob": knob, "value": value,
                "default": geometry == default and oversample == 0,
                "psf_size_px": geometry.psf_size_px, "pupil_samples": geometry.pupil_samples,
                "oversample": oversample,
                "psf_l1": float((_embed(psf, ref_k) - ref).abs().sum(dim=(1, 2)).mean()),
                "image_psnr_db": float(psnr(image, ref_image)[0]),
                "psf_grad_ms": _psf_grad_ms(spec_v, geometry, oversample, repeats),
                "reference": {"psf_size_px": ref_k, "pupil_samples": ref_geometry.pupil_samples,
                              "oversample": 0,
                              "energy_fraction": float(ref.sum(dim=(1, 2)).min())},
            })
    return records


def run(path: Path, scene: torch.Tensor, repeats: int = 5) -> Path:
    """Measure and write the study JSON (records and provenance) to ``path``."""
    body = {"study": "psf_grid", "scene_shape": list(scene.shape), "repeats": repeats,
            "timing_threads": 1, "records": measure(scene, repeats), "provenance": provenance("cpu")}
    atomic_write_text(path, json.dumps(body, indent=1, sort_keys=True) + "\n")
    return path
