"""``nafnet-known-psf``: a restorer that learned the whole lens family once and is told the lens's PSF.

Lens-access threat model (as ``wiener-known-psf``): the attacker measured the camera's PSF and gain.
It Wiener-deconvolves the sensor image with them and hands the estimate, beside the white-balanced
sensor image, to a NAFNet pre-trained once across the family of the registry's lenses
(``attacks.training.psf_restorer_training``, ``attacks.training.lens_family``), which returns the
estimate plus a learned correction. Nothing is trained per lens.

Weights: the package ships the pre-training of the full budget (quick and paper profiles; made by
``python -m benchmark pretrain-attacker nafnet-known-psf``, provenance and held-out curve beside the
file in ``attacks/weights/``), found by its key (budget, family, training scenes, seed). Where they
are missing (tiny and smoke runs, whose small budget is never shipped, or a deleted file) it
pre-trains on the run's own TRAIN pairs' sharp images, the last quarter of them held out, and caches
the result under a key naming those images.
"""

from __future__ import annotations

import json
import logging
import struct
from typing import Any, ClassVar

import torch
from safetensors import SafetensorError
from safetensors.torch import load as load_safetensors
from safetensors.torch import save as save_safetensors
from torch import Tensor

from attacks.backends.real_fft import OtfCache
from attacks.base import ArtifactStore, FitContext, FitReport, Restorer, ThreatModel
from attacks.backends.onnx_runtime import InferenceEngine, check_backend
from attacks.networks.nafnet import NAFNet
from attacks.networks.nafnet_folded import fold_for_inference
from attacks.training.lens_family import LensFamily
from attacks.training.psf_restorer_training import (
    PretrainCurve,
    PsfPretrainBudget,
    build_network,
    pretrain,
    psf_budget,
    psf_inputs,
)
from attacks.training.restorer_training import collect_pairs, data_identity, fingerprint
from attacks.training.fit_code import versioned_key
from attacks.training.shipped_weights import Shipped, find_shipped

__all__ = ["SHIPPED_SCENES", "NafnetKnownPSF", "known_psf_key", "load_cached", "pack", "restore_known_psf", "shipped_key",
           "unpack"]

log = logging.getLogger(__name__)

SHIPPED_SCENES = {"scenes": "synthetic", "train_split": "train", "n_train": 64, "heldout_split": "test",
                  "n_heldout": 2, "size": [512, 1024], "scene_seed": 0}
"""The scenes the shipped pre-training saw (loaded by ``benchmark.publish.ship_attacker``)."""

PRETRAIN_SEED = 0
"""One pre-trained attacker serves every run seed, as one set of GoPro weights would."""


def shipped_key(budget: PsfPretrainBudget, data: Any = None) -> dict[str, Any]:
    """The key the pre-training is cached and shipped under: budget, family, training scenes, seed."""
    return versioned_key(NafnetKnownPSF.name, {"attack": NafnetKnownPSF.name, "budget": budget.to_dict(),
                                               "family": LensFamily().describe(),
                                               "data": SHIPPED_SCENES if data is None else data, "seed": PRETRAIN_SEED})


def pack(net: NAFNet, curve: PretrainCurve) -> bytes:
    """Safetensors bytes of the network, its curve in the metadata."""
    state = {k: v.detach().cpu().contiguous() for k, v in net.state_dict().items()}
    return save_safetensors(state, metadata={"kind": NafnetKnownPSF.name, "curve": json.dumps(curve.to_dict())})


def unpack(data: bytes, budget: PsfPretrainBudget) -> tuple[NAFNet, PretrainCurve | None]:
    """The network (and curve, when stored) of ``pack``'s bytes; raises on bytes of another layout."""
    net = build_network(budget, PRETRAIN_SEED)
    net.load_state_dict(load_safetensors(data), strict=True)
    metadata = _metadata(data)
    curve = PretrainCurve.from_dict(json.loads(metadata["curve"])) if "curve" in metadata else None
    return net.eval(), curve


def load_cached(artifacts: ArtifactStore | None, kind: str, key: dict[str, Any], budget: PsfPretrainBudget
                ) -> tuple[NAFNet, PretrainCurve | None] | None:
    """The network and curve ``pack`` stored in the artifact store under (kind, key); None when there are
    none, or when the stored bytes do not unpack (logged: the caller trains again and overwrites them)."""
    stored = None if artifacts is None else artifacts.load(kind, key)
    if stored is None:
        return None
    try:
        return unpack(stored, budget)
    except (SafetensorError, RuntimeError, KeyError, ValueError) as exc:
        log.warning("%s: cached weights unreadable (%s); training again", kind, exc)
        return None


def restore_known_psf(engine: InferenceEngine, sensor: Tensor, otf: OtfCache, gain: Tensor) -> Tensor:
    """Scene estimates (B, 3, H, W) in [0, 1] of sensor images: the Wiener stage, then the network, one
    image at a time (the six-channel input of a whole batch of frames would be large)."""
    return torch.cat([engine(psf_inputs(sensor[i:i + 1].cpu(), otf, gain)).clamp(0.0, 1.0)
                      for i in range(sensor.shape[0])]).to(sensor.device)


def known_psf_key(network: NAFNet | None, otf: OtfCache | None, gain: Tensor | None, backend: str) -> str | None:
    """What ``restore_known_psf`` returns depends on: the network's weights, the PSF and gain, the backend
    (None before a fit). Shared by every restorer that restores through ``restore_known_psf``."""
    if network is None or otf is None or gain is None:
        return None
    weights = (v for _, v in sorted(network.state_dict().items()))
    return f"restore_known_psf/{backend}/{fingerprint(*weights, otf.psf, gain)}"


def _metadata(data: bytes) -> dict[str, str]:
    """The ``__metadata__`` of safetensors bytes (its header: an 8-byte length, then JSON)."""
    n = struct.unpack("<Q", data[:8])[0]
    return json.loads(data[8:8 + n]).get("__metadata__", {})


class NafnetKnownPSF(Restorer):
    """Wiener with the measured PSF, refined by a NAFNet pre-trained across the lens family.

    Args:
        use_shipped: Load the package's pre-training when its key matches (default); False pre-trains
            (or loads from the run's cache).
        backend: Inference backend of the network, "onnx" (default: the folded network through ONNX
            Runtime, torch where it is not on the CPU), "auto" or "torch" (``attacks.backends.onnx_runtime``).

    Attributes:
        shipped: After ``fit``: the shipped weights used, or None.
        curve: After ``fit``: the pre-training's held-out curve (None for weights cached without one).
        trained: After ``fit``: True if it pre-trained in this fit.
    """

    name: ClassVar[str] = "nafnet-known-psf"
    threat_model: ClassVar[ThreatModel] = ThreatModel.LENS_ACCESS
    learns: ClassVar[bool] = True
    requires: ClassVar[frozenset[str]] = frozenset({"lens"})

    def __init__(self, use_shipped: bool = True, backend: str = "onnx") -> None:
        self.use_shipped = use_shipped
        self.backend = check_backend(backend)
        self.engine: InferenceEngine | None = None
        self.shipped: Shipped | None = None
        self.curve: PretrainCurve | None = None
        self.trained: bool | None = None
        self.network: NAFNet | None = None
        self.budget: PsfPretrainBudget | None = None
        self._otf: OtfCache | None = None
        self._gain: Tensor | None = None

    def fit(self, ctx: FitContext) -> FitReport:
        """Measure the lens (PSF, gain) and load the pre-trained network (or pre-train it, module docs)."""
        assert ctx.lens is not None  # checked by `requires`
        self._otf = OtfCache(ctx.lens.psf().detach().cpu())
        self._gain = ctx.lens.gain().detach().cpu()
        self.network, self.curve, self.trained = self.load_pretrained(ctx)
        self.network = self.network.to(ctx.device).eval()
        self.engine = InferenceEngine(fold_for_inference(self.network), self.backend, fallback=True)
        if self.curve is None:
            return FitReport()
        return FitReport(curve=self.curve.to_fit_curve(), still_rising=self.curve.still_rising,
                         stage_seconds={"pretrain": self.curve.seconds} if self.trained else {})

    def load_pretrained(self, ctx: FitContext) -> tuple[NAFNet, PretrainCurve | None, bool]:
        """The pre-trained network of the context's budget, its curve, and whether it was pre-trained now:
        the shipped weights, else the cache's, else a pre-training on ``ctx.train_pairs`` (module docs)."""
        self.budget = budget = psf_budget(ctx.budget.profile)
        key = shipped_key(budget)
        if self.use_shipped:
            self.shipped = find_shipped(self.name, key)
            if self.shipped is not None:
                log.info("%s: pre-trained weights shipped with the package (%s)", self.name, self.shipped.path.name)
                net, curve = unpack(self.shipped.data, budget)
                return net, curve, False
        if ctx.train_pairs is None:
            raise ValueError(f"{self.name}: no shipped pre-training for this budget and no TRAIN pairs to "
                             "pre-train on (FitContext.train_pairs)")
        _, sharp = collect_pairs(ctx.train_pairs, 64)
        if sharp.shape[0] < 2:
            raise ValueError(f"{self.name}: pre-training needs at least 2 TRAIN scenes (one held out), got {sharp.shape[0]}")
        key = shipped_key(budget, data_identity(sharp))
        cached = load_cached(ctx.artifacts, self.name, key, budget)
        if cached is not None:
            return cached[0], cached[1], False
        log.warning("%s: no shipped pre-training for the %s budget; pre-training on this run's %d TRAIN scenes",
                    self.name, "small" if budget.max_steps < 100 else "full", sharp.shape[0])
        held = max(1, sharp.shape[0] // 4)
        net, curve = pretrain(budget, sharp[:-held], sharp[-held:], PRETRAIN_SEED)
        if ctx.artifacts is not None:
            ctx.artifacts.save(self.name, key, pack(net, curve))
        return net, curve, True

    def restore(self, sensor: Tensor) -> Tensor:
        """Scene estimate: (B, 3, H, W) in [0, 1] -> (B, 3, H, W) in [0, 1]."""
        if self.engine is None or self._otf is None or self._gain is None:
            raise RuntimeError(f"{self.name}: call fit(ctx) before restore()")
        return restore_known_psf(self.engine, sensor, self._otf, self._gain)

    def restoration_key(self) -> str | None:
        """The network's weights, the PSF and gain it is fed, and the backend (``known_psf_key``)."""
        return known_psf_key(self.network, self._otf, self._gain, self.backend)

    def describe(self) -> dict[str, Any]:
        """Configuration: budget, the pre-training's provenance and held-out score."""
        described = {**super().describe(), "backend": self.backend,
                     "budget": None if self.budget is None else self.budget.to_dict(),
                     "input": "wiener(psf, gain, bayer noise) + white-balanced sensor", "per_lens_training": False}
        if self.shipped is not None:
            described["shipped_weights"] = self.shipped.describe()
        if self.curve is not None and self.curve.heldout_psnr_db:
            described["pretrain_heldout_psnr_db"] = max(self.curve.heldout_psnr_db)
            described["pretrain_wiener_psnr_db"] = self.curve.wiener_psnr_db
        return described
