"""``nafnet-generic``: a generic deblurring NAFNet that knows nothing of the lens under test.

The sensor-access adversary (paper Sec. 4.2, "Pretrained NAFNet / DeblurGAN-v2"): it only sees
the camera's sensor images. The paper used GoPro-pretrained weights, which cannot be
downloaded here, so by default a stand-in is trained in-suite ONCE on generic degradations
(``attacks.training.degradations``: identity, Gaussian, motion and disk kernels, random tint,
Poisson-Gaussian noise, a generic Bayer pipeline) of sharp TRAIN crops. Its cache key holds the
budget, the training crops and the seed but no lens, so every lens shares the same model. The package
ships the model of the ``quick`` profile at seed 0 (``attacks/weights/``, ``attacks.training.shipped_weights``),
made by this same training (``python -m benchmark pretrain-attacker nafnet-generic``): it is loaded
when its key equals the run's, so a fresh machine does not spend the fit on it.

Before deblurring, the tint is removed by gray-world white balance, as the paper corrects the
white balance by hand; the training inputs get the same balance, so the network learns to
undo what gray-world leaves (overall exposure).

Passing ``checkpoint=PATH`` (an official NAFNet GoPro file, ``.pth`` or ``.safetensors``)
uses those weights instead of training; ``checkpoint_arch`` overrides the GoPro architecture
(width 32, ``enc_blk_nums=(1, 1, 1, 28)``) for other variants.
"""

from __future__ import annotations

import hashlib
import logging
from pathlib import Path
from typing import Any, ClassVar

import torch
from torch import Tensor

from attacks.base import FitContext, FitReport, Restorer, ThreatModel
from attacks.training.degradations import degrade
from attacks.restorers.gray_world import gray_world_balance
from attacks.networks.nafnet import NAFNet, load_nafnet_checkpoint
from attacks.networks.nafnet_folded import fold_for_inference
from attacks.backends.onnx_runtime import InferenceEngine, check_backend
from attacks.training.shipped_weights import Shipped
from attacks.training.restorer_training import (
    RestorerBudget,
    collect_pairs,
    data_identity,
    random_crops,
    shipped_or_fit,
)

__all__ = ["NafnetGeneric"]

log = logging.getLogger(__name__)


class NafnetGeneric(Restorer):
    """Gray-world white balance, then a NAFNet trained on generic degradations (or a checkpoint).

    Args:
        checkpoint: Path of a local NAFNet checkpoint to use instead of training; None trains.
        checkpoint_arch: ``NAFNet`` keyword arguments of the checkpoint (None: GoPro width 32).
        backend: Inference backend: "onnx", "auto" or "torch" (``attacks.backends.onnx_runtime``).
            ONNX Runtime by default (torch where the network is not on the CPU or the export
            fails): it runs the folded quick NAFNet faster than torch, and "auto"'s one-image probe
            has picked the slower one (docs/modelling.md, docs/history.md).
        use_shipped: Load the package's shipped weights when their key matches (False: train or
            load from the cache, as ``pretrain-attacker`` does to make them).

    Attributes:
        trained: After ``fit``: True if it trained, False if the weights came from the cache,
            the package or the checkpoint.
        shipped: After ``fit``: the shipped weights used, or None.
        network: After ``fit``: the NAFNet (trained, shipped or the checkpoint's).
        engine: After ``fit``: the inference engine, running ``network`` folded for inference
            (``attacks.networks.nafnet_folded``).
    """

    name: ClassVar[str] = "nafnet-generic"
    threat_model: ClassVar[ThreatModel] = ThreatModel.SENSOR_ACCESS
    learns: ClassVar[bool] = True

    def __init__(self, checkpoint: str | Path | None = None, checkpoint_arch: dict[str, Any] | None = None,
                 backend: str = "onnx", use_shipped: bool = True) -> None:
        self.checkpoint = None if checkpoint is None else Path(checkpoint)
        if self.checkpoint is not None and not self.checkpoint.is_file():
            raise FileNotFoundError(f"{self.name}: checkpoint {str(self.checkpoint)!r} does not exist")
        self.checkpoint_arch = dict(checkpoint_arch or {})
        self.backend = check_backend(backend)
        self.use_shipped = use_shipped
        self.shipped: Shipped | None = None
        self.budget: RestorerBudget | None = None
        self.trained: bool | None = None
        self.network: NAFNet | None = None
        self.engine: InferenceEngine | None = None
        self._checkpoint_sha256: str | None = None

    def fit(self, ctx: FitContext) -> FitReport:
        """Load the checkpoint, or train on generic degradations of ``ctx.train_pairs``' sharp
        crops (loading from ``ctx.artifacts`` when cached)."""
        if self.checkpoint is not None:
            model = load_nafnet_checkpoint(self.checkpoint, **self.checkpoint_arch)
            self._checkpoint_sha256 = hashlib.sha256(self.checkpoint.read_bytes()).hexdigest()
            self.trained = False
        else:
            if ctx.train_pairs is None:
                raise ValueError(f"{self.name}: without checkpoint=PATH it trains, and needs "
                                 "FitContext.train_pairs (sharp TRAIN crops)")
            budget = RestorerBudget.from_budget(ctx.budget)
            _, sharp = collect_pairs(ctx.train_pairs, budget.max_train_images)
            key = self._key(budget, sharp, ctx.seed)

            def next_batch(generator: torch.Generator) -> tuple[Tensor, Tensor]:
                (target,) = random_crops([sharp], budget.batch_size, budget.crop_px, generator)
                return gray_world_balance(degrade(target, generator)), target

            model, self.trained, self.shipped = shipped_or_fit(budget, ctx, self.name, key, next_batch,
                                                              self.use_shipped)
            self.budget = budget
        self.network = model.to(ctx.device).eval()
        self.engine = InferenceEngine(fold_for_inference(self.network), self.backend, fallback=True)
        return FitReport()

    def cache_key(self, ctx: FitContext) -> dict[str, Any]:
        """The configuration its trained weights are cached (and shipped) under: budget, training crops, seed."""
        if ctx.train_pairs is None:
            raise ValueError(f"{self.name}: the cache key needs FitContext.train_pairs (sharp TRAIN crops)")
        budget = RestorerBudget.from_budget(ctx.budget)
        _, sharp = collect_pairs(ctx.train_pairs, budget.max_train_images)
        return self._key(budget, sharp, ctx.seed)

    def _key(self, budget: RestorerBudget, sharp: Tensor, seed: int) -> dict[str, Any]:
        return {"attack": self.name, "budget": budget.to_dict(), "data": data_identity(sharp), "seed": seed}

    def restore(self, sensor: Tensor) -> Tensor:
        """Scene estimate: (B, 3, H, W) in [0, 1] -> (B, 3, H, W) in [0, 1]."""
        if self.engine is None:
            raise RuntimeError(f"{self.name}: call fit(ctx) before restore()")
        return self.engine(gray_world_balance(sensor)).clamp(0.0, 1.0)

    def describe(self) -> dict[str, Any]:
        """Configuration: weights source (checkpoint and its SHA-256, or training budget)."""
        source: dict[str, Any]
        if self.checkpoint is not None:
            source = {"checkpoint": str(self.checkpoint), "checkpoint_sha256": self._checkpoint_sha256,
                      "checkpoint_arch": self.checkpoint_arch}
        else:
            source = {"budget": None if self.budget is None else self.budget.to_dict(),
                      "training": "generic kernels (identity, gaussian, motion, disk), tint, poisson-gaussian"}
            if self.shipped is not None:
                source["shipped_weights"] = self.shipped.describe()
        return {**super().describe(), "backend": self.backend, "white_balance": "gray-world", **source}
