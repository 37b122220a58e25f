"""A camera: an encoder (phase mask, or a measured PSF) plus sensor, as one differentiable torch module."""

from __future__ import annotations

import dataclasses
from pathlib import Path

import torch

from lenses.convolve import apply_otf, convolve, fft_shape, psf_otf, uses_fft
from lenses.measured import read_psf_channels, sensor_psf, sha256_of
from lenses.optics import Geometry, PupilModel, choose_geometry
from lenses.sensor import Sensor
from lenses.spec import LensSpec, LensSpecError


def measured_psf(spec: LensSpec) -> tuple[torch.Tensor, torch.Tensor]:
    """A measured-PSF spec's PSF on its sensor grid (3, K, K) float32, each channel summing to 1, and the
    energy fraction (3,) of the measured images inside it (`lenses.measured.sensor_psf`).

    Raises LensSpecError when a file no longer holds what the spec was validated against (its sha256).
    """
    m = spec.measured_psf
    if m is None:
        raise ValueError(f"lens spec {spec.name!r} is a {spec.kind} lens, not a measured PSF")
    paths = [Path(f) for f in m.files]
    for i, (path, digest) in enumerate(zip(paths, m.sha256)):
        if sha256_of(path) != digest:
            raise LensSpecError(f"measured_psf.files[{i}] ({path}) changed since the spec was read "
                                f"(measured_psf.sha256[{i}] = {digest!r}); load the spec again")
    psf, fraction = sensor_psf(read_psf_channels(paths), m.pixel_pitch_um, spec.sensor.pixel_pitch_um,
                               spec.simulation.max_psf_size_px)
    return torch.from_numpy(psf).to(torch.float32), torch.from_numpy(fraction).to(torch.float32)


class Lens(torch.nn.Module):
    """Scene radiance (B,3,H,W) in [0,1] -> sensor image (B,3,H,W) in [0,1].

    The PSF comes from the spec's encoder: a phase mask (Zernike terms, or a height map from a file, whose
    `coefficients_um` is empty) through `pupil` (Fourier optics), or a measured PSF used as given (`pupil`
    None, geometry.pupil_samples 0, `coefficients_um` empty).
    `coefficients_um` (n,) holds the n Noll Zernike coefficients of the mask thickness in um of
    glass; it is a trainable parameter when the spec declares bounds. Grid sizes are fixed at
    construction (from the bounds for trainable masks), so nothing changes shape while training.

    ``utility_net``, ``adversary`` and ``training_record``: what co-design trained with this lens (None
    for a fixed lens).
    """

    utility_net: torch.nn.Module | None
    adversary: torch.nn.Module | None
    measured: torch.Tensor  # buffers of a measured-PSF lens: its PSF (3, K, K) and energy fraction (3,)
    measured_energy: torch.Tensor
    height_scale: torch.Tensor
    training_record: dict | None

    def __init__(self, spec: LensSpec, geometry: Geometry | None = None):
        super().__init__()
        self.spec = spec
        self.pupil: PupilModel | None = None
        if spec.measured_psf is not None:
            psf, fraction = measured_psf(spec)
            geometry = Geometry(0, psf.shape[-1])
            self.initial_energy_fraction = fraction
            self.register_buffer("measured", psf, persistent=False)
            self.register_buffer("measured_energy", fraction, persistent=False)
        elif geometry is None:
            geometry, fraction = choose_geometry(spec)
            self.initial_energy_fraction = fraction
        self.geometry = geometry
        self.coefficients_um = torch.nn.Parameter(torch.tensor(spec.mask.zernike_um, dtype=torch.float32),
                                                  requires_grad=spec.mask.trainable)
        if spec.measured_psf is None:
            self.pupil = PupilModel(spec, geometry)
        # A height map is the pupil model's one basis term, at a fixed scale of 1 (not trained).
        self.register_buffer("height_scale", torch.ones(1, dtype=torch.float64), persistent=False)
        self.sensor = Sensor(spec.sensor, spec.optics.aperture_diameter_mm)
        # Networks co-designed with this lens and the record of that training (set by
        # benchmark.codesign); plain attributes, not submodules, so that lens.parameters() stays
        # the optics alone. Not `training`: that is torch's train/eval flag.
        object.__setattr__(self, "utility_net", None)
        object.__setattr__(self, "adversary", None)
        object.__setattr__(self, "training_record", None)
        # OTFs of the current PSF per (transform size, dtype, device), each with the coefficients it
        # was made from: the forward of a lens that is not being differentiated reuses them.
        self._otf_cache: dict[tuple, tuple[tuple[float, ...], torch.Tensor]] = {}
        self._psf_cache: tuple[tuple[float, ...], torch.Tensor] | None = None

    @property
    def name(self) -> str:
        return self.spec.name

    def psf_and_energy(self) -> tuple[torch.Tensor, torch.Tensor]:
        """PSF (3,K,K) with channels R,G,B each summing to 1, and the energy fraction (3,) it holds."""
        if self.pupil is None:
            return self.measured, self.measured_energy
        return self.pupil(self.height_scale if self.spec.height_map is not None else self.coefficients_um)

    def psf(self) -> torch.Tensor:
        """PSF (3,K,K), sensor-pixel sampling, each channel sums to 1; ideal peak at [K//2, K//2]."""
        return self.psf_and_energy()[0]

    def gain(self) -> torch.Tensor:
        """Expected sensor value per unit scene radiance, per channel (3,) (QE and exposure tint)."""
        return self.sensor.gain()

    def white_balance(self, sensor: torch.Tensor) -> torch.Tensor:
        """The camera's white balance: sensor images (B,3,H,W) divided by the known per-channel gain,
        clamped to [0, 1]. What the utility network sees (and the `identity` attacker returns)."""
        return (sensor / self.gain().to(sensor).view(1, -1, 1, 1)).clamp(0.0, 1.0)

    def irradiance(self, x: torch.Tensor) -> torch.Tensor:
        """Noise-free optical image on the sensor (B,3,H,W): the scene convolved with the PSF."""
        k = self.geometry.psf_size_px
        if not uses_fft(k) or (torch.is_grad_enabled() and self.coefficients_um.requires_grad):
            return convolve(x, self.psf().to(x.device))
        return apply_otf(x, self.cached_otf(fft_shape(x.shape[-2], x.shape[-1], k), x.dtype, x.device), k)

    def cached_otf(self, shape: tuple[int, int], dtype: torch.dtype, device: torch.device) -> torch.Tensor:
        """OTF (3, h, w//2+1) of the current PSF on an (h, w) transform grid, without gradient.

        Cached per grid, dtype and device; an entry is used only while the coefficients still hold
        the values it was made from (an optimiser step, a load_state_dict or a clamp all change them).
        """
        coefficients = tuple(self.coefficients_um.detach().cpu().tolist())
        key = (shape, dtype, device)
        entry = self._otf_cache.get(key)
        if entry is None or entry[0] != coefficients:
            # Outside inference mode, so that the cached tensor may later meet tensors that need grad.
            with torch.inference_mode(False), torch.no_grad():
                otf = psf_otf(self._psf_without_grad(coefficients).to(device=device, dtype=dtype), shape)
            if len(self._otf_cache) >= 8:  # a few image sizes at most; drop the oldest
                self._otf_cache.pop(next(iter(self._otf_cache)))
            entry = self._otf_cache[key] = (coefficients, otf)
        return entry[1]

    def _psf_without_grad(self, coefficients: tuple[float, ...]) -> torch.Tensor:
        """The PSF (3,K,K) for the OTF cache, computed once per set of coefficients: plate windows
        come in many sizes, and each new transform size would otherwise recompute it (about 30 ms)."""
        if self._psf_cache is None or self._psf_cache[0] != coefficients:
            self._psf_cache = (coefficients, self.psf().detach())
        return self._psf_cache[1]

    def forward(self, x: torch.Tensor, generator: torch.Generator | None = None) -> torch.Tensor:
        if x.ndim != 4 or x.shape[1] != 3:
            raise ValueError(f"lens input must be (B,3,H,W) scene radiance, got shape {tuple(x.shape)}")
        return self.sensor(self.irradiance(x), generator=generator)

    @torch.no_grad()
    def clamp_to_bounds(self) -> None:
        """Project the coefficients back inside the bounds the spec declares (after an optimiser step)."""
        if self.spec.mask.bounds_um is None:
            return
        lo, hi = (torch.tensor(b, dtype=self.coefficients_um.dtype, device=self.coefficients_um.device)
                  for b in zip(*self.spec.mask.bounds_um))
        self.coefficients_um.copy_(torch.maximum(torch.minimum(self.coefficients_um, hi), lo))

    def current_spec(self) -> LensSpec:
        """The spec with the current coefficients (a learned lens is itself a spec)."""
        mask = dataclasses.replace(self.spec.mask, zernike_um=tuple(float(c) for c in self.coefficients_um.detach().cpu()),
                                   random_seed=None)
        return dataclasses.replace(self.spec, mask=mask)
