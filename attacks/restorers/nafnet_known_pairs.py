"""``nafnet-known-pairs``: NAFNet trained on (sensor image, sharp scene) pairs of the lens under test.

The known-pairs adversary (paper Sec. 4.2, "Trained NAFNet"): it has aligned pairs from the
camera's TRAIN split and trains a dedicated restorer with NAFNet's recipe (negative PSNR,
AdamW, cosine schedule; ``attacks.training.restorer_training``), sized by the profile
(``restorer_steps``, ``nafnet_width``, ``nafnet_*_blocks``). The weights are cached per
(lens spec, budget, training data, seed), so a second run loads them; the package ships them for
the lens it ships (``benchmark.codesign.shipped``), under the same key.
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
    lens_key,
    random_crops,
    shipped_or_fit,
)
from attacks.training.shipped_weights import Shipped

__all__ = ["NafnetKnownPairs"]


class NafnetKnownPairs(Restorer):
    """NAFNet trained on the lens's own TRAIN pairs; restores sensor images directly.

    Args:
        backend: Inference backend, "onnx", "auto" (time torch and ONNX Runtime once, keep the
            faster) or "torch" (``attacks.backends.onnx_runtime``).
            ONNX Runtime by default (torch where the network is not on the CPU or the export
            fails): it runs the folded quick NAFNet faster than torch, and "auto"'s one-image probe
            has picked the slower one (docs/modelling.md, docs/history.md).
        use_shipped: Load the package's weights shipped for exactly this lens, budget, training pairs
            and seed (``attacks.training.shipped_weights``; made with the lens by ``python -m benchmark
            ship-lens``) when they exist; False trains or loads from the cache.

    Attributes:
        trained: After ``fit``: True if it trained, False if the weights came from the cache or the package.
        shipped: After ``fit``: the shipped weights used, or None.
        network: After ``fit``: the trained NAFNet.
        engine: After ``fit``: the inference engine (``engine.backend`` says which is in use), running
            ``network`` folded for inference (``attacks.networks.nafnet_folded``).
    """

    name: ClassVar[str] = "nafnet-known-pairs"
    threat_model: ClassVar[ThreatModel] = ThreatModel.KNOWN_PAIRS
    requires: ClassVar[frozenset[str]] = frozenset({"lens", "train_pairs"})

    def __init__(self, backend: str = "onnx", use_shipped: bool = True) -> None:
        self.backend = check_backend(backend)
        self.use_shipped = use_shipped
        self.shipped: Shipped | None = None
        self.budget: RestorerBudget | None = None
        self.trained: bool | None = None
        self.network: NAFNet | None = None
        self.engine: InferenceEngine | None = None

    def fit(self, ctx: FitContext) -> FitReport:
        """Train (or load from ``ctx.artifacts``) a NAFNet on ``ctx.train_pairs``."""
        assert ctx.lens is not None and ctx.train_pairs is not None  # checked by `requires`
        budget = RestorerBudget.from_budget(ctx.budget)
        sensor, sharp = collect_pairs(ctx.train_pairs, budget.max_train_images)
        key = self._key(budget, ctx, sensor, sharp)

        def next_batch(generator: torch.Generator) -> tuple[Tensor, Tensor]:
            inp, target = random_crops([sensor, sharp], budget.batch_size, budget.crop_px, generator)
            return inp, target

        model, self.trained, self.shipped = shipped_or_fit(budget, ctx, self.name, key, next_batch, self.use_shipped)
        self.budget = budget
        self.network = model.to(ctx.device).eval()
        self.engine = InferenceEngine(fold_for_inference(self.network), self.backend, fallback=True)
        return FitReport()

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

    def restore(self, sensor: Tensor) -> Tensor:
        """Scene estimate: (B, 3, H, W) in [0, 1] -> (B, 3, H, W) in [0, 1]."""
        if self.engine is None:
            raise RuntimeError(f"{self.name}: call fit(ctx) before restore()")
        return self.engine(sensor).clamp(0.0, 1.0)

    def describe(self) -> dict[str, Any]:
        """Configuration: backend option, training budget and recipe."""
        described = {**super().describe(), "backend": self.backend,
                     "budget": None if self.budget is None else self.budget.to_dict(),
                     "recipe": "nafnet: -psnr, adamw 1e-3, cosine"}
        if self.shipped is not None:
            described["shipped_weights"] = self.shipped.describe()
        return described

