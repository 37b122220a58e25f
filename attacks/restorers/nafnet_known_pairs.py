"""``nafnet-known-pairs``: a NAFNet fitted to (sensor image, sharp scene) pairs of the lens under test.

The known-pairs adversary (paper Sec. 4.2, "Trained NAFNet"): it has aligned pairs from the
camera's TRAIN split. Two starts (``start``):

- "known-psf": it measures the camera's effective PSF and gain from its pairs
  (``attacks.training.pair_psf``: it is not given them), and fine-tunes the restorer pre-trained
  across the lens family (``nafnet-known-psf``, fed the Wiener estimate with the measured PSF) on the
  pairs until the held-out PSNR of the last eighth of them flattens on a log-step axis
  (``attacks.training.psf_restorer_training.fine_tune``; at most ``FINE_TUNE_STEPS_FACTOR`` times the
  profile's ``restorer_steps``; the pre-trained start is kept unless a step beats it by the stop rule's
  0.05 dB).
- "scratch" (default): a NAFNet of the profile's size (``restorer_steps``, ``nafnet_width``, ``nafnet_*_blocks``)
  trained from random weights with NAFNet's recipe (``attacks.training.restorer_training``).

The weights are cached per (start, lens spec, budget, training data, seed), so a second run loads them;
the package ships the scratch fit for the lens it ships (``benchmark.codesign.shipped``), under its key.
"""

from __future__ import annotations

from typing import Any, ClassVar

import torch
from torch import Tensor

from attacks.base import FitContext, FitReport, Restorer, ThreatModel
from attacks.networks.nafnet import NAFNet
from attacks.networks.nafnet_folded import fold_for_inference
from attacks.backends.onnx_runtime import InferenceEngine, check_backend
from attacks.training.restorer_training import (
    RestorerBudget,
    collect_pairs,
    data_identity,
    fingerprint,
    lens_key,
    random_crops,
    shipped_or_fit,
)
from attacks.training.shipped_weights import Shipped
from attacks.backends.real_fft import OtfCache
from attacks.training.pair_psf import estimate_psf
from attacks.training.fit_code import versioned_key
from attacks.restorers.nafnet_known_psf import NafnetKnownPSF, known_psf_key, load_cached, pack, restore_known_psf
from attacks.training.psf_restorer_training import PretrainCurve, centre, fine_tune, psf_inputs

__all__ = ["ESTIMATED_PSF_PX", "FINE_TUNE_STEPS_FACTOR", "STARTS", "NafnetKnownPSFTuned", "NafnetKnownPairs", "NafnetKnownPairsTuned"]

STARTS = ("known-psf", "scratch")
FINE_TUNE_STEPS_FACTOR = 8
"""A known-psf start's fine-tune runs at most this many times the profile's ``restorer_steps`` (three more
doublings of its log-step axis): on the sharp lenses its held-out PSNR still rose at ``restorer_steps``
(ideal +1.55 dB at 200 quick steps), on the blurring ones it stops at the first evaluation."""
ESTIMATED_PSF_PX = 95
"""Side of the PSF the known-psf start estimates (the family's largest support is 87 px), at most the scenes' side."""


class NafnetKnownPairs(Restorer):
    """A NAFNet fitted to the lens's own TRAIN pairs (module docs); restores sensor images.

    Args:
        start: "known-psf" (fine-tune the family's pre-trained restorer, fed the PSF measured from the
            pairs) or "scratch" (train the profile's NAFNet from random weights).
        backend: Inference backend of the scratch network, "onnx", "auto" or "torch"
            (``attacks.backends.onnx_runtime``; ONNX Runtime runs the folded quick NAFNet faster than torch).
        use_shipped: Use weights shipped in the package when their key matches (the scratch fit of the
            shipped lens; the family pre-training the known-psf start begins from); False trains or
            loads from the cache.

    Attributes:
        trained: After ``fit``: True if it trained, False if the weights came from the cache or the package.
        shipped: After ``fit``: the shipped weights used, or None.
        network: After ``fit``: the network.
        curve: After a known-psf ``fit``: the fine-tune's held-out curve (step 0 is the pre-trained start).
    """

    name: ClassVar[str] = "nafnet-known-pairs"
    _psf_source: ClassVar[str] = "pair-measured"
    threat_model: ClassVar[ThreatModel] = ThreatModel.KNOWN_PAIRS
    learns: ClassVar[bool] = True
    requires: ClassVar[frozenset[str]] = frozenset({"lens", "train_pairs"})

    def __init__(self, start: str = "scratch", backend: str = "onnx", use_shipped: bool = True) -> None:
        if start not in STARTS:
            raise ValueError(f"nafnet-known-pairs: start must be one of {', '.join(STARTS)}, got {start!r}")
        self.start = start
        self.backend = check_backend(backend)
        self.use_shipped = use_shipped
        self.shipped: Shipped | None = None
        self.budget: RestorerBudget | None = None
        self.trained: bool | None = None
        self.network: NAFNet | None = None
        self.engine: InferenceEngine | None = None
        self.curve: PretrainCurve | None = None
        self._otf: OtfCache | None = None
        self._gain: Tensor | None = None

    def fit(self, ctx: FitContext) -> FitReport:
        """Fine-tune (known-psf) or train (scratch) on ``ctx.train_pairs``, or load from ``ctx.artifacts``."""
        assert ctx.lens is not None and ctx.train_pairs is not None  # checked by `requires`
        budget = RestorerBudget.from_budget(ctx.budget)
        sensor, sharp = collect_pairs(ctx.train_pairs, budget.max_train_images)
        self.budget = budget
        if self.start == "known-psf":
            return self._fit_known_psf(ctx, budget, sensor, sharp)
        key = self._key(budget, ctx, sensor, sharp)

        def next_batch(generator: torch.Generator) -> tuple[Tensor, Tensor]:
            inp, target = random_crops([sensor, sharp], budget.batch_size, budget.crop_px, generator)
            return inp, target

        model, self.trained, self.shipped = shipped_or_fit(budget, ctx, self.name, key, next_batch, self.use_shipped)
        self.network = model.to(ctx.device).eval()
        self.engine = InferenceEngine(fold_for_inference(self.network), self.backend, fallback=True)
        return FitReport()

    def _fit_known_psf(self, ctx: FitContext, budget: RestorerBudget, sensor: Tensor, sharp: Tensor) -> FitReport:
        def ready(net: NAFNet) -> FitReport:
            self.network = net
            self.engine = InferenceEngine(fold_for_inference(net), self.backend, fallback=True)
            return self._report()

        if sensor.shape[0] < 2:
            raise ValueError(f"{self.name}: the known-psf start needs at least 2 TRAIN pairs (some held out), "
                             f"got {sensor.shape[0]}")
        psf, gain = self._camera(ctx, sensor, sharp)
        self._otf, self._gain = OtfCache(psf), gain
        start = NafnetKnownPSF(use_shipped=self.use_shipped)
        net, _, _ = start.load_pretrained(ctx)
        self.shipped = start.shipped
        key = versioned_key(self.name, {**self._key(budget, ctx, sensor, sharp), "start": self.start,
                                        "pretrained": fingerprint(*(v for _, v in sorted(net.state_dict().items())))})
        assert start.budget is not None  # set by load_pretrained
        cached = load_cached(ctx.artifacts, self.name, key, start.budget)
        if cached is not None:
            self.trained = False
            net, self.curve = cached
            return ready(net)
        inputs = psf_inputs(sensor, self._otf, gain)
        held = max(1, sensor.shape[0] // 8)
        self.curve = fine_tune(net, inputs[:-held], sharp[:-held], centre(inputs[-held:]), centre(sharp[-held:]),
                               max_steps=FINE_TUNE_STEPS_FACTOR * budget.steps, crop_px=budget.crop_px,
                               batch_size=budget.batch_size,
                               seed=ctx.seed, device=ctx.device)
        self.trained = True
        if ctx.artifacts is not None:
            ctx.artifacts.save(self.name, key, pack(net, self.curve))
        return ready(net)

    def _camera(self, ctx: FitContext, sensor: Tensor, sharp: Tensor) -> tuple[Tensor, Tensor]:
        """The PSF (3, K, K) and gain (3,) the fine-tune feeds its start: measured from the pairs (``pair_psf``)."""
        size = min(ESTIMATED_PSF_PX, (min(sensor.shape[-2:]) - 1) // 2 * 2 + 1)
        return estimate_psf(sensor, sharp, size)

    def _report(self) -> FitReport:
        assert self.curve is not None
        return FitReport(curve=self.curve.to_fit_curve(), still_rising=self.curve.still_rising,
                         stage_seconds={"fine-tune": self.curve.seconds} if self.trained else {})

    def cache_key(self, ctx: FitContext) -> dict[str, Any]:
        """The configuration its weights are cached (and shipped) under: budget, lens, training pairs, seed."""
        if ctx.lens is None or ctx.train_pairs is None:
            raise ValueError(f"{self.name}: the cache key needs FitContext.lens and FitContext.train_pairs")
        budget = RestorerBudget.from_budget(ctx.budget)
        sensor, sharp = collect_pairs(ctx.train_pairs, budget.max_train_images)
        return self._key(budget, ctx, sensor, sharp)

    def _key(self, budget: RestorerBudget, ctx: FitContext, sensor: Tensor, sharp: Tensor) -> dict[str, Any]:
        return {"attack": self.name, "budget": budget.to_dict(), "lens": lens_key(ctx.lens),
                "data": data_identity(sensor, sharp), "seed": ctx.seed}

    def restoration_key(self) -> str | None:
        """The known-psf start's: its network, PSF, gain and backend (``known_psf_key``), so a fine-tune that
        kept its start with the lens's own PSF is ``nafnet-known-psf`` to the runner; the scratch start's None."""
        return known_psf_key(self.network, self._otf, self._gain, self.backend) if self.start == "known-psf" else None

    def restore(self, sensor: Tensor) -> Tensor:
        """Scene estimate: (B, 3, H, W) in [0, 1] -> (B, 3, H, W) in [0, 1]."""
        if self.start == "known-psf":
            if self.engine is None or self._otf is None or self._gain is None:
                raise RuntimeError(f"{self.name}: call fit(ctx) before restore()")
            return restore_known_psf(self.engine, sensor, self._otf, self._gain)
        if self.engine is None:
            raise RuntimeError(f"{self.name}: call fit(ctx) before restore()")
        return self.engine(sensor).clamp(0.0, 1.0)

    def describe(self) -> dict[str, Any]:
        """Configuration: start, backend option, training budget and recipe."""
        recipe = (f"{self._psf_source} psf + wiener, fine-tune of nafnet-known-psf: -psnr, adamw 2e-4, cosine, "
                  "log-step stop" if self.start == "known-psf" else "nafnet: -psnr, adamw 1e-3, cosine")
        described = {**super().describe(), "start": self.start, "backend": self.backend,
                     "budget": None if self.budget is None else self.budget.to_dict(), "recipe": recipe}
        if self.shipped is not None:
            described["shipped_weights"] = self.shipped.describe()
        if self.curve is not None and self.curve.heldout_psnr_db:
            described["fine_tune_heldout_psnr_db"] = {"start": self.curve.heldout_psnr_db[0],
                                                      "kept": max(self.curve.heldout_psnr_db),
                                                      "kept_step": self.curve.kept_step}
        return described


class NafnetKnownPairsTuned(NafnetKnownPairs):
    """``nafnet-known-pairs-tuned``: the known-psf start of ``nafnet-known-pairs`` (module docs), its own row:
    the PSF and gain measured from the pairs, the family's pre-trained restorer fine-tuned on them."""

    name: ClassVar[str] = "nafnet-known-pairs-tuned"

    def __init__(self, backend: str = "onnx", use_shipped: bool = True) -> None:
        super().__init__(start="known-psf", backend=backend, use_shipped=use_shipped)


class NafnetKnownPSFTuned(NafnetKnownPairsTuned):
    """``nafnet-known-psf-tuned`` (lens access, which assumes the known pairs too): the family's pre-trained
    restorer fed the lens's own PSF and gain, as ``nafnet-known-psf`` is, and fine-tuned on the lens's TRAIN
    pairs until their held-out PSNR flattens. Its step 0 is ``nafnet-known-psf`` itself, and the fine-tune
    keeps the start unless a step beats it by 0.05 dB on the held-out pairs."""

    name: ClassVar[str] = "nafnet-known-psf-tuned"
    threat_model: ClassVar[ThreatModel] = ThreatModel.LENS_ACCESS
    _psf_source: ClassVar[str] = "the lens's"

    def _camera(self, ctx: FitContext, sensor: Tensor, sharp: Tensor) -> tuple[Tensor, Tensor]:
        """The lens's measured PSF and gain (``ctx.lens``), as ``nafnet-known-psf`` takes them."""
        assert ctx.lens is not None  # checked by `requires`
        with torch.no_grad():
            return ctx.lens.psf().detach().cpu(), ctx.lens.gain().detach().cpu()
