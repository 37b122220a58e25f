"""Lens specifications: TOML files with validated fields whose names carry their units.

A spec is the whole camera: optics, phase mask, sensor and simulation settings. Only `name` and the
mask coefficients are required; everything else takes the physical defaults of the dataclasses below.
Any problem (missing field, unknown key, wrong type or unit, NaN, out-of-range value) raises
LensSpecError naming the offending field.
"""

from __future__ import annotations

import dataclasses
import itertools
import math
import os
import tomllib
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from lenses.materials import MATERIALS, refractive_index
from common.plugins import suggest
from lenses.zernike import zernike_noll

N_ZERNIKE = 6  # terms of the built-in masks and of a random draw (Noll Z1..Z6)
# A spec's mask may hold any number of Noll terms up to this (radial order 10); the pupil-sampling
# guard (lenses.optics.pupil_samples_for) refuses any that the pupil grid cannot resolve.
MAX_ZERNIKE = 66


class LensSpecError(ValueError):
    """A lens spec is malformed; the message names the field and what would be valid."""


@dataclass(frozen=True)
class OpticsSpec:
    focal_length_mm: float = 25.0
    aperture_diameter_mm: float = 5.0
    object_distance_m: float = 10.0
    focus_distance_m: float = 10.0  # object distance the sensor plane is focused on
    wavelengths_nm: tuple[float, float, float] = (640.0, 550.0, 460.0)
    mask_material: str = "fused-silica"


@dataclass(frozen=True)
class MaskSpec:
    zernike_um: tuple[float, ...] = (0.0,) * N_ZERNIKE  # glass thickness, Noll Z1..Zn, RMS-normalised
    bounds_um: tuple[tuple[float, float], ...] | None = None  # per-term bounds: declares a trainable mask
    random_seed: int | None = None  # draws zernike_um uniformly in [-random_amplitude_um, +] (Z2..Z6)
    random_amplitude_um: float = 0.0
    # The largest peak-to-valley relief (um of glass) the mask may have to be made; with bounds_um,
    # every mask inside the bounds must stay within it (checked), so the bounds are a
    # manufacturing limit rather than a tuning choice.
    max_sag_um: float | None = None

    @property
    def trainable(self) -> bool:
        return self.bounds_um is not None


@dataclass(frozen=True)
class SensorSpec:
    pixel_pitch_um: float = 3.45
    reference_aperture_diameter_mm: float = 5.0  # intensity scales as (D / D_ref)^2
    white_level_photons: float = 15000.0  # photons per pixel for scene radiance 1 at D_ref
    quantum_efficiency: tuple[float, float, float] = (0.45, 0.60, 0.50)
    full_well_e: float = 10000.0
    read_noise_e: float = 2.0
    adc_bits: int = 10


@dataclass(frozen=True)
class SimulationSpec:
    # PSF support holds at least this energy. 0.99 rather than 0.999: the last 0.9 % lies in faint
    # diffraction rings out to ~260 px; cropping them changes a convolved image by 56 dB PSNR,
    # 13 dB below the sensor's own shot noise at mid-grey, at a 7x smaller K (docs/modelling.md, measured).
    psf_energy_fraction: float = 0.99
    max_psf_size_px: int = 129
    max_pupil_samples: int = 1024


@dataclass(frozen=True)
class MeasuredPsfSpec:
    """A PSF measured with a point source: the optics of the lens are these images, used as given."""

    files: tuple[str, ...]  # 1 (all channels, or R, G, B in one image) or 3 (R, G, B); absolute paths here,
    # relative to the spec's folder in `LensSpec.to_dict` (what keys and results hold: no machine's paths)
    pixel_pitch_um: float  # pitch of the measured images' pixels on the sensor plane
    sha256: tuple[str, ...]  # of each file's bytes: the spec (and every cache key) changes with the data
    measured_on: str = ""  # the sensor (and setup) the PSF was measured with; provenance only


@dataclass(frozen=True)
class HeightMapSpec:
    """A phase mask given as a glass thickness map in a file (the formats `export-mask` writes); fixed."""

    file: str  # absolute path (relative to the spec's folder in `LensSpec.to_dict`); .npy, .tif/.tiff (heights in
    # um), .dat (Zemax Grid Sag), .csv (x_mm, y_mm, height_um)
    sample_pitch_um: float  # node spacing on the mask; the central node lies on the optical axis
    sha256: str  # of the file's bytes: the spec (and every cache key) changes with the data


@dataclass(frozen=True)
class LensSpec:
    name: str
    optics: OpticsSpec = field(default_factory=OpticsSpec)
    mask: MaskSpec = field(default_factory=MaskSpec)
    sensor: SensorSpec = field(default_factory=SensorSpec)
    simulation: SimulationSpec = field(default_factory=SimulationSpec)
    description: str = ""
    source: str = ""  # where the spec came from (path or "builtin:NAME"); provenance only
    # The encoder when it is not a Zernike mask (then mask.zernike_um is empty); at most one is set.
    measured_psf: MeasuredPsfSpec | None = None
    height_map: HeightMapSpec | None = None

    @property
    def kind(self) -> str:
        """The encoder: "zernike" (a phase mask of mask.zernike_um), "measured-psf" or "height-map"."""
        if self.measured_psf is not None:
            return "measured-psf"
        return "height-map" if self.height_map is not None else "zernike"

    def to_dict(self, absolute_paths: bool = False) -> dict[str, Any]:
        """Plain TOML-ready dict (without `source`); a Zernike lens's dict holds no key of the other kinds.

        The files a spec names are written relative to the spec's folder (`spec_folder`), so the dict (a
        cache key, a results file, a leaderboard entry) is the same wherever the spec and its files lie;
        the files' sha256 say what they hold. `absolute_paths` writes them as this machine finds them.
        """
        d = dataclasses.asdict(self)
        d.pop("source")
        for key in ENCODER_SECTIONS:
            if d[key] is None:
                d.pop(key)
        if not absolute_paths:
            base = spec_folder(self.source)
            if "measured_psf" in d:
                d["measured_psf"]["files"] = tuple(_relative(f, base) for f in d["measured_psf"]["files"])
            if "height_map" in d:
                d["height_map"]["file"] = _relative(d["height_map"]["file"], base)
        if d["mask"]["bounds_um"] is None:
            d["mask"].pop("bounds_um")
        if d["mask"]["random_seed"] is None:
            d["mask"].pop("random_seed")
        if d["mask"]["max_sag_um"] is None:
            d["mask"].pop("max_sag_um")
        return d


_SECTIONS = {"optics": OpticsSpec, "mask": MaskSpec, "sensor": SensorSpec, "simulation": SimulationSpec}
# Sections that replace the Zernike mask as the lens's encoder, with their kind's name.
ENCODER_SECTIONS = {"measured_psf": "measured-psf", "height_map": "height-map"}
KINDS = ("zernike", *ENCODER_SECTIONS.values())
KIND_DESCRIPTIONS = {
    "zernike": "[mask] zernike_um: a phase mask of any number of Noll terms in um of glass (with bounds_um: "
               "co-designed)",
    "measured-psf": "[measured_psf] files, pixel_pitch_um: a PSF measured with a point source (one image per "
                    "channel or one for all), used as given; not co-designed",
    "height-map": "[height_map] file, sample_pitch_um or diameter_mm: a freeform phase mask as a glass thickness "
                  "map (the formats export-mask writes); not co-designed",
}
_TOP = {"name", "description", *_SECTIONS, *ENCODER_SECTIONS}


def _number(value: Any, where: str) -> float:
    if isinstance(value, bool) or not isinstance(value, (int, float)):
        raise LensSpecError(f"{where} must be a number, got {type(value).__name__} {value!r}")
    if not math.isfinite(value):
        raise LensSpecError(f"{where} must be finite, got {value!r}")
    return float(value)


def _positive(value: Any, where: str, allow_zero: bool = False) -> float:
    v = _number(value, where)
    if v < 0 or (v == 0 and not allow_zero):
        raise LensSpecError(f"{where} must be {'>= 0' if allow_zero else '> 0'}, got {v!r}")
    return v


def _vector(value: Any, where: str, length: int | None) -> tuple[float, ...]:
    if not isinstance(value, list):
        raise LensSpecError(f"{where} must be a list of numbers, got {type(value).__name__} {value!r}")
    if length is not None and len(value) != length:
        raise LensSpecError(f"{where} must have {length} entries, got {len(value)}")
    return tuple(_number(v, f"{where}[{i}]") for i, v in enumerate(value))


def _integer(value: Any, where: str, minimum: int) -> int:
    if isinstance(value, bool) or not isinstance(value, int):
        raise LensSpecError(f"{where} must be an integer, got {type(value).__name__} {value!r}")
    if value < minimum:
        raise LensSpecError(f"{where} must be >= {minimum}, got {value}")
    return value


def _check_keys(table: dict, allowed: set[str], where: str) -> None:
    for key in table:
        if key not in allowed:
            prefix = f"{where}." if where else ""
            raise LensSpecError(
                f"unknown key {prefix}{key!r}; valid keys here: {sorted(allowed)}.{suggest(key, allowed)}"
                " (field names carry their unit, e.g. focal_length_mm)"
            )


# Keys that older specs (and the leaderboard entries that store them) carry but that no longer mean
# anything: `simulation.oversample` chose the s x s sub-pixel sums that exact pixel integration replaced.
_OBSOLETE_KEYS = {"simulation": {"oversample"}}


def _section(raw: dict, name: str) -> dict:
    table = raw.get(name, {})
    if not isinstance(table, dict):
        raise LensSpecError(f"[{name}] must be a table, got {type(table).__name__}")
    table = {k: v for k, v in table.items() if k not in _OBSOLETE_KEYS.get(name, set())}
    _check_keys(table, {f.name for f in dataclasses.fields(_SECTIONS[name])}, name)
    return table


def _optics(t: dict) -> OpticsSpec:
    d = OpticsSpec()
    kw: dict[str, Any] = {}
    for key in ("focal_length_mm", "aperture_diameter_mm", "object_distance_m", "focus_distance_m"):
        kw[key] = _positive(t.get(key, getattr(d, key)), f"optics.{key}")
    wl = _vector(list(t.get("wavelengths_nm", list(d.wavelengths_nm))), "optics.wavelengths_nm", 3)
    for i, w in enumerate(wl):
        if not 300.0 <= w <= 1100.0:
            raise LensSpecError(f"optics.wavelengths_nm[{i}] = {w} is not a visible/NIR wavelength in nm (300-1100)")
    material = t.get("mask_material", d.mask_material)
    if not isinstance(material, str):
        raise LensSpecError(f"optics.mask_material must be a string naming a material (one of {sorted(MATERIALS)}), "
                            f"got {type(material).__name__} {material!r}")
    if material not in MATERIALS:
        raise LensSpecError(f"optics.mask_material {material!r} is unknown; known: {sorted(MATERIALS)}")
    if kw["focus_distance_m"] * 1000.0 <= kw["focal_length_mm"]:
        raise LensSpecError("optics.focus_distance_m must exceed the focal length, else no real image forms")
    return OpticsSpec(wavelengths_nm=wl, mask_material=material, **kw)  # type: ignore[arg-type]


def _mask(t: dict) -> MaskSpec:
    seed = t.get("random_seed")
    amplitude = _positive(t.get("random_amplitude_um", 0.0), "mask.random_amplitude_um", allow_zero=True)
    if seed is not None:
        seed = _integer(seed, "mask.random_seed", 0)
        if "zernike_um" in t:
            raise LensSpecError("mask.zernike_um and mask.random_seed are exclusive: give one of them")
        rng = np.random.default_rng(seed)
        coeffs = (0.0, *rng.uniform(-amplitude, amplitude, N_ZERNIKE - 1).tolist())
    elif "zernike_um" in t:
        coeffs = _vector(t["zernike_um"], "mask.zernike_um", None)
        if not 1 <= len(coeffs) <= MAX_ZERNIKE:
            raise LensSpecError(f"mask.zernike_um must hold 1 to {MAX_ZERNIKE} Noll coefficients (um of glass, "
                                f"Z1 first), got {len(coeffs)}")
    else:
        raise LensSpecError(f"missing field mask.zernike_um (a list of Noll coefficients in um of glass, Z1 first, "
                            f"e.g. {N_ZERNIKE} of them) or mask.random_seed")
    bounds = None
    if "bounds_um" in t:
        raw = t["bounds_um"]
        if not isinstance(raw, list) or len(raw) != len(coeffs):
            raise LensSpecError(f"mask.bounds_um must be a list of {len(coeffs)} [low, high] pairs in um, one per "
                                "entry of mask.zernike_um")
        bounds = tuple(_vector(b, f"mask.bounds_um[{i}]", 2) for i, b in enumerate(raw))
        for i, ((lo, hi), c) in enumerate(zip(bounds, coeffs)):
            if not lo <= c <= hi:
                raise LensSpecError(f"mask.zernike_um[{i}] = {c} lies outside mask.bounds_um[{i}] = [{lo}, {hi}]")
    max_sag = None
    if "max_sag_um" in t:
        max_sag = _positive(t["max_sag_um"], "mask.max_sag_um")
        worst = worst_sag_um(bounds if bounds is not None else tuple((c, c) for c in coeffs))
        if worst > max_sag:
            what = "the worst mask inside mask.bounds_um" if bounds is not None else "mask.zernike_um"
            raise LensSpecError(f"{what} has a peak-to-valley relief of {worst:.3f} um, more than mask.max_sag_um = "
                                f"{max_sag}; narrow the bounds or raise max_sag_um")
    return MaskSpec(zernike_um=tuple(coeffs), bounds_um=bounds, random_seed=seed,
                    random_amplitude_um=amplitude, max_sag_um=max_sag)  # type: ignore[arg-type]


# Polar grid over the closed unit disk (rim included, where the relief peaks) for worst_sag_um.
_RHO, _THETA = np.meshgrid(np.linspace(0.0, 1.0, 201), np.linspace(0.0, 2 * np.pi, 361))
# Beyond this many corners of the box of bounds, worst_sag_um maximises over pairs of pupil points.
MAX_SAG_CORNERS = 4096
_RHO_PAIRS, _THETA_PAIRS = np.meshgrid(np.linspace(0.0, 1.0, 41), np.linspace(0.0, 2 * np.pi, 97))


def worst_sag_um(bounds_um: tuple[tuple[float, float], ...]) -> float:
    """Largest peak-to-valley relief (um) of any mask h = sum_j c_j Z_j with lo_j <= c_j <= hi_j.

    The relief max(h) - min(h) over the pupil is convex in c, so its maximum over the box of
    bounds lies at a corner; with up to MAX_SAG_CORNERS corners each is evaluated on a polar grid
    (201 radii x 361 angles, rim included), which resolves the relief of low orders to about 1e-4
    relative. With more free terms the same maximum is taken the other way round: for two pupil
    points p, q the box's largest h(p) - h(q) is sum_j max(lo_j d_j, hi_j d_j) with
    d_j = Z_j(p) - Z_j(q), maximised over the pairs of a coarser grid (41 radii x 97 angles).
    """
    n_corners = math.prod(len({lo, hi}) for lo, hi in bounds_um)
    if n_corners <= MAX_SAG_CORNERS:
        basis = np.stack([zernike_noll(j + 1, _RHO, _THETA).ravel() for j in range(len(bounds_um))])
        corners = np.array(list(itertools.product(*[sorted({lo, hi}) for lo, hi in bounds_um])))
        relief = corners @ basis
        return float((relief.max(axis=1) - relief.min(axis=1)).max())
    basis = np.stack([zernike_noll(j + 1, _RHO_PAIRS, _THETA_PAIRS).ravel() for j in range(len(bounds_um))]).T
    lo, hi = (np.array(b) for b in zip(*bounds_um))
    worst = 0.0
    for start in range(0, basis.shape[0], 256):  # (256, points, terms) differences at a time
        d = basis[start:start + 256, None, :] - basis[None, :, :]
        worst = max(worst, float(np.maximum(d * lo, d * hi).sum(axis=-1).max()))
    return worst


# What the float32 sensor model can represent. Its noise model and the ideal observer's likelihood
# square electron counts (variance mean + read^2, m * m summed over a frame's pixels): counts up to
# 1e15 keep those squares (1e30) and their sums far inside float32's 3.4e38, and a real sensor
# holds 1e3-1e6 electrons. A float32 sensor value tells 2**24 integer levels apart, hence the ADC's bits.
MAX_ELECTRONS = 1e15
ADC_BITS_RANGE = (1, 24)


def _bounded(value: float, where: str, low: str, high: float) -> float:
    if value > high:
        raise LensSpecError(f"{where} = {value!r} is more than the float32 sensor model represents; "
                            f"valid: {low} to {high:g}")
    return value


def _sensor(t: dict) -> SensorSpec:
    d = SensorSpec()
    kw: dict[str, Any] = {}
    for key in ("pixel_pitch_um", "reference_aperture_diameter_mm", "white_level_photons", "full_well_e"):
        kw[key] = _positive(t.get(key, getattr(d, key)), f"sensor.{key}")
    kw["read_noise_e"] = _positive(t.get("read_noise_e", d.read_noise_e), "sensor.read_noise_e", allow_zero=True)
    for key in ("white_level_photons", "full_well_e", "read_noise_e"):
        _bounded(kw[key], f"sensor.{key}", ">= 0" if key == "read_noise_e" else "> 0", MAX_ELECTRONS)
    qe = _vector(list(t.get("quantum_efficiency", list(d.quantum_efficiency))), "sensor.quantum_efficiency", 3)
    for i, q in enumerate(qe):
        if not 0.0 < q <= 1.0:
            raise LensSpecError(f"sensor.quantum_efficiency[{i}] = {q} must lie in (0, 1]")
    bits = _integer(t.get("adc_bits", d.adc_bits), "sensor.adc_bits", ADC_BITS_RANGE[0])
    if bits > ADC_BITS_RANGE[1]:
        raise LensSpecError(f"sensor.adc_bits = {bits} is more than a float32 sensor value resolves; "
                            f"valid: {ADC_BITS_RANGE[0]} to {ADC_BITS_RANGE[1]}")
    kw["adc_bits"] = bits
    return SensorSpec(quantum_efficiency=qe, **kw)  # type: ignore[arg-type]


MAX_PSF_SIZE_PX = 1025   # simulation.max_psf_size_px at most (the studies' reference uses 301)
MAX_PUPIL_SAMPLES = 8192  # simulation.max_pupil_samples at most (1 GiB per complex128 grid; the reference uses 4096)


def _simulation(t: dict) -> SimulationSpec:
    d = SimulationSpec()
    frac = _number(t.get("psf_energy_fraction", d.psf_energy_fraction), "simulation.psf_energy_fraction")
    if not 0.5 < frac < 1.0:
        raise LensSpecError(f"simulation.psf_energy_fraction = {frac} must lie in (0.5, 1)")
    max_k = _integer(t.get("max_psf_size_px", d.max_psf_size_px), "simulation.max_psf_size_px", 3)
    if max_k % 2 == 0:
        raise LensSpecError(f"simulation.max_psf_size_px = {max_k} must be odd (the PSF has a centre pixel)")
    if max_k > MAX_PSF_SIZE_PX:
        raise LensSpecError(f"simulation.max_psf_size_px = {max_k} is too large; valid: 3 to {MAX_PSF_SIZE_PX} (odd): a "
                            "wider kernel is an image of its own, and every convolution pads the image by it")
    samples = _integer(t.get("max_pupil_samples", d.max_pupil_samples), "simulation.max_pupil_samples", 32)
    if samples > MAX_PUPIL_SAMPLES:
        raise LensSpecError(f"simulation.max_pupil_samples = {samples} is too large; valid: 32 to {MAX_PUPIL_SAMPLES} "
                            f"(one {samples} x {samples} complex pupil grid is {samples ** 2 * 16 / 2 ** 30:.1f} GiB, "
                            "and the PSF needs several per wavelength)")
    return SimulationSpec(psf_energy_fraction=frac, max_psf_size_px=max_k, max_pupil_samples=samples)


def spec_folder(source: str) -> Path:
    """The folder a spec's relative file names are read from: its .toml's folder, else the working directory."""
    return (Path(source).parent if source.endswith(".toml") else Path.cwd()).resolve()


def _relative(path: str, base: Path) -> str:
    """`path` relative to `base`, with "/" (``..`` where it lies outside); `path` itself on another drive."""
    try:
        return Path(os.path.relpath(path, base)).as_posix()
    except ValueError:  # Windows: another drive has no relative path
        return path


def _file(value: Any, where: str, base: Path) -> Path:
    """An existing file named by a spec, relative to the spec's folder."""
    if not isinstance(value, str) or not value:
        raise LensSpecError(f"{where} must be a file path (a string), got {type(value).__name__} {value!r}")
    path = (base / Path(value).expanduser()).resolve()
    if not path.is_file():
        raise LensSpecError(f"{where}: file {value!r} does not exist ({path}; a relative path is read from the "
                            "spec file's folder)")
    return path


def _checked_hashes(t: dict, where: str, paths: list[Path]) -> tuple[str, ...]:
    from lenses.measured import sha256_of
    actual = tuple(sha256_of(p) for p in paths)
    if "sha256" in t:
        given = t["sha256"]
        if not isinstance(given, list) or len(given) != len(paths) or not all(isinstance(h, str) for h in given):
            raise LensSpecError(f"{where}.sha256 must be a list of {len(paths)} hex strings, one per file, "
                                f"got {given!r}")
        for i, (g, a) in enumerate(zip(given, actual)):
            if g.lower() != a:
                raise LensSpecError(f"{where}.sha256[{i}] = {g!r} does not match the content of {paths[i]} (the "
                                    f"file changed since the spec was written); valid: {a!r}, or leave sha256 out")
    return actual


def _measured_psf(t: dict, base: Path) -> MeasuredPsfSpec:
    from lenses.measured import read_psf_channels
    _check_keys(t, {f.name for f in dataclasses.fields(MeasuredPsfSpec)}, "measured_psf")
    files = t.get("files")
    if files is None:
        raise LensSpecError("missing field measured_psf.files (a list of 1 image for all three channels, or "
                            "3 images R, G, B: .npy, .tif/.tiff or .png)")
    if not isinstance(files, list):
        raise LensSpecError(f"measured_psf.files must be a list of 1 or 3 file paths, got {type(files).__name__} "
                            f"{files!r}")
    if "pixel_pitch_um" not in t:
        raise LensSpecError("missing field measured_psf.pixel_pitch_um (the pitch in um of the measured image's "
                            "pixels on the sensor plane, e.g. 3.45 when measured on the suite's sensor)")
    pitch = _positive(t["pixel_pitch_um"], "measured_psf.pixel_pitch_um")
    measured_on = t.get("measured_on", "")
    if not isinstance(measured_on, str):
        raise LensSpecError(f"measured_psf.measured_on must be a string, got {type(measured_on).__name__}")
    paths = [_file(f, f"measured_psf.files[{i}]", base) for i, f in enumerate(files)]
    try:
        read_psf_channels(paths)
    except ValueError as exc:
        text = str(exc)
        raise LensSpecError(f"measured_psf.files{'' if text.startswith('[') else ' '}{text}") from None
    return MeasuredPsfSpec(files=tuple(str(p) for p in paths), pixel_pitch_um=pitch,
                           sha256=_checked_hashes(t, "measured_psf", paths), measured_on=measured_on)


def _no_mask(raw: dict, section: str) -> None:
    """Refuse a Zernike mask beside another encoder; the empty mask `to_dict` writes for one is fine."""
    table = raw.get("mask", {})
    empty = isinstance(table, dict) and table.get("zernike_um", []) in ([], ()) and \
        set(table) <= {"zernike_um", "random_amplitude_um"} and table.get("random_amplitude_um", 0.0) == 0.0
    if empty:
        return
    kind = ENCODER_SECTIONS[section]
    if isinstance(table, dict) and "bounds_um" in table:
        raise LensSpecError(f"mask.bounds_um asks to co-design the lens, but a {kind} lens ([{section}]) has no "
                            "optical parameters to train; drop mask.bounds_um (only a Zernike mask is co-designed)")
    raise LensSpecError(f"[mask] and [{section}] are two encoders; give one of them ([{section}] is the whole "
                        "optics of the lens, it takes no mask coefficients)")


def _height_map(t: dict, base: Path, optics: OpticsSpec) -> HeightMapSpec:
    from lenses.height_file import max_steps_um, read_height_map
    _check_keys(t, {"file", "sample_pitch_um", "diameter_mm", "sha256"}, "height_map")
    if "file" not in t:
        raise LensSpecError("missing field height_map.file (a glass thickness map: .npy, .tif/.tiff in um, "
                            ".dat Zemax Grid Sag or .csv, as export-mask writes)")
    path = _file(t["file"], "height_map.file", base)
    try:
        data = read_height_map(path)
    except ValueError as exc:
        raise LensSpecError(f"height_map.file ({path}) {exc}") from None
    n_y, n_x = data.height_um.shape
    if "sample_pitch_um" in t and "diameter_mm" in t:
        raise LensSpecError("height_map.sample_pitch_um and height_map.diameter_mm both state the grid; give one")
    if "sample_pitch_um" in t:
        pitch = _positive(t["sample_pitch_um"], "height_map.sample_pitch_um")
    elif "diameter_mm" in t:  # the span of the longer side, edge node to edge node
        pitch = _positive(t["diameter_mm"], "height_map.diameter_mm") * 1000.0 / (max(n_x, n_y) - 1)
    elif data.spacing_um is not None:
        pitch = data.spacing_um
    else:
        raise LensSpecError(f"missing field height_map.sample_pitch_um (the node spacing in um) or "
                            f"height_map.diameter_mm (the span edge node to edge node): {path.suffix} files do not "
                            "state their grid")
    if data.spacing_um is not None and not math.isclose(pitch, data.spacing_um, rel_tol=1e-6):
        raise LensSpecError(f"the grid stated in the spec ({pitch:.6g} um between nodes) is not the one "
                            f"height_map.file states ({data.spacing_um:.6g} um); drop it or make it agree")
    span_mm = (min(n_x, n_y) - 1) * pitch / 1000.0
    if span_mm < optics.aperture_diameter_mm * (1 - 1e-9):
        raise LensSpecError(f"height_map.file spans {span_mm:.6g} mm ({min(n_x, n_y)} nodes {pitch:.6g} um apart), "
                            f"less than optics.aperture_diameter_mm = {optics.aperture_diameter_mm}; valid: a map "
                            "covering the whole aperture")
    radius = optics.aperture_diameter_mm * 500.0
    yy, xx = np.meshgrid((np.arange(n_y) - (n_y - 1) / 2) * pitch, (np.arange(n_x) - (n_x - 1) / 2) * pitch,
                         indexing="ij")
    holes = int((np.isnan(data.height_um) & (np.hypot(xx, yy) <= radius - 1.5 * pitch)).sum())
    if holes:
        raise LensSpecError(f"height_map.file ({path}) has {holes} NaN nodes inside the clear aperture; valid: "
                            "heights at every node of the aperture (NaN only outside it)")
    # A step between neighbouring nodes of more than pi of phase at the shortest wavelength is not
    # resolved by the map itself: no pupil grid could tell it from a smaller step the other way.
    per_um, wavelength = max((2 * math.pi * (refractive_index(optics.mask_material, w) - 1) / (w * 1e-3), w)
                             for w in optics.wavelengths_nm)
    step = max(max_steps_um(np.where(np.hypot(xx, yy) <= radius + pitch, data.height_um, np.nan)))
    if step * per_um > math.pi:
        raise LensSpecError(f"height_map.file ({path}) has a step of {step:.4g} um of glass between neighbouring "
                            f"nodes, {step * per_um:.3g} rad at {wavelength:g} nm: more than pi, "
                            f"so the map aliases; valid: steps up to {math.pi / per_um:.4g} um (sample it finer)")
    given = {"sha256": [t["sha256"]]} if isinstance(t.get("sha256"), str) else {k: t[k] for k in ("sha256",) if k in t}
    return HeightMapSpec(file=str(path), sample_pitch_um=pitch, sha256=_checked_hashes(given, "height_map", [path])[0])


def _encoder(raw: dict, source: str, optics: OpticsSpec
             ) -> tuple[MaskSpec, MeasuredPsfSpec | None, HeightMapSpec | None]:
    given = [key for key in ENCODER_SECTIONS if key in raw]
    if not given:
        return _mask(_section(raw, "mask")), None, None
    if len(given) > 1:
        raise LensSpecError(f"{' and '.join(f'[{k}]' for k in given)} are two encoders; give one of them")
    _no_mask(raw, given[0])
    table = raw[given[0]]
    if not isinstance(table, dict):
        raise LensSpecError(f"[{given[0]}] must be a table, got {type(table).__name__}")
    base = spec_folder(source)
    if given[0] == "height_map":
        return MaskSpec(zernike_um=()), None, _height_map(table, base, optics)
    return MaskSpec(zernike_um=()), _measured_psf(table, base), None


def parse_spec(raw: dict, source: str = "") -> LensSpec:
    """Validate a spec dict (as read from TOML) into a frozen LensSpec.

    Files that the spec names (a measured PSF's images) are read relative to the folder of `source`
    when it is a .toml path, else to the working directory, and checked here: a bad file fails at load.
    """
    _check_keys(raw, _TOP, "")
    if "name" not in raw:
        raise LensSpecError(f"missing field 'name' in lens spec {source or '(dict)'}")
    name = raw["name"]
    if not isinstance(name, str) or not name.strip():
        raise LensSpecError(f"name must be a non-empty string, got {name!r}")
    description = raw.get("description", "")
    if not isinstance(description, str):
        raise LensSpecError(f"description must be a string, got {type(description).__name__}")
    optics, sensor = _optics(_section(raw, "optics")), _sensor(_section(raw, "sensor"))
    mask, measured_psf, height_map = _encoder(raw, source, optics)
    # The electrons a pixel collects at radiance 1 scale with the aperture's area: the two fields
    # in range apart may still multiply past what the sensor model represents.
    electrons = sensor.white_level_photons * (optics.aperture_diameter_mm / sensor.reference_aperture_diameter_mm) ** 2
    if not electrons <= MAX_ELECTRONS:
        raise LensSpecError(
            f"sensor.white_level_photons = {sensor.white_level_photons!r} times (optics.aperture_diameter_mm / "
            f"sensor.reference_aperture_diameter_mm)^2 = {electrons:.4g} photons per pixel, more than the float32 "
            f"sensor model represents; valid: > 0 to {MAX_ELECTRONS:g}")
    return LensSpec(
        name=name,
        description=description,
        optics=optics,
        mask=mask,
        sensor=sensor,
        simulation=_simulation(_section(raw, "simulation")),
        source=source,
        measured_psf=measured_psf,
        height_map=height_map,
    )


def load_spec(path: str | Path) -> LensSpec:
    """Read and validate a lens spec TOML file."""
    path = Path(path)
    try:
        raw = tomllib.loads(path.read_text(encoding="utf-8"))
    except FileNotFoundError:
        raise LensSpecError(f"lens spec file {str(path)!r} does not exist") from None
    except (tomllib.TOMLDecodeError, UnicodeDecodeError) as exc:
        raise LensSpecError(f"lens spec {str(path)!r} is not valid TOML: {exc}") from None
    try:
        return parse_spec(raw, source=str(path))
    except LensSpecError as exc:
        raise LensSpecError(f"{path}: {exc}") from None


def _toml_value(v: Any) -> str:
    if isinstance(v, bool):
        return "true" if v else "false"
    if isinstance(v, str):
        return '"' + v.replace("\\", "\\\\").replace('"', '\\"') + '"'
    if isinstance(v, (list, tuple)):
        return "[" + ", ".join(_toml_value(x) for x in v) + "]"
    return repr(float(v)) if isinstance(v, float) else repr(v)


def spec_to_toml(spec: LensSpec) -> str:
    """Serialise a spec to TOML text that `load_spec` reads back to an equal spec, wherever the text is
    written (the files it names are written as absolute paths)."""
    d = spec.to_dict(absolute_paths=True)
    if d["mask"].get("random_seed") is not None:
        d["mask"].pop("random_seed")  # the drawn coefficients are written out instead
    lines = [f"name = {_toml_value(d['name'])}", f"description = {_toml_value(d['description'])}"]
    sections = [s for s in (*_SECTIONS, *ENCODER_SECTIONS) if s in d and not (s == "mask" and spec.kind != "zernike")]
    for section in sections:
        lines += ["", f"[{section}]"] + [f"{k} = {_toml_value(v)}" for k, v in d[section].items()]
    return "\n".join(lines) + "\n"
