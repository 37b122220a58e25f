"""``training-adversary``: the RED10 deblurring adversary from the lens's own co-design run.

The paper's first deblurring attack (Table 2, "Adversarial training"): the network that was
trained jointly with the lens to restore its sensor images. Contract with ``benchmark.codesign``:
a co-designed lens carries the attribute ``adversary``, a ``torch.nn.Module`` mapping sensor
images (B, 3, H, W) in [0, 1] to scene estimates; fixed lenses have none, and the attacker is
skipped for them (``skip_reason``).
"""

from __future__ import annotations

import copy
from typing import Any, ClassVar

from torch import Tensor, nn

from attacks.base import FitContext, FitReport, Restorer, ThreatModel
from attacks.backends.onnx_runtime import InferenceEngine, check_backend

__all__ = ["TrainingAdversary"]


class TrainingAdversary(Restorer):
    """Restores with ``ctx.adversary`` (a frozen copy), clamped to [0, 1].

    Args:
        backend: Inference backend: "onnx", "auto" or "torch" (``attacks.backends.onnx_runtime``).
            ONNX Runtime by default (torch where the network is not on the CPU or the export
            fails): it restores the quick RED10's plate windows faster than torch and at a lower
            peak, and "auto"'s one-image probe has picked torch (docs/modelling.md, docs/history.md).
    """

    name: ClassVar[str] = "training-adversary"
    threat_model: ClassVar[ThreatModel] = ThreatModel.TRAINING_ADVERSARY
    learns: ClassVar[bool] = True
    requires: ClassVar[frozenset[str]] = frozenset({"adversary"})

    def __init__(self, backend: str = "onnx") -> None:
        self.backend = check_backend(backend)
        self.engine: InferenceEngine | None = None
        self._network: str | None = None

    def skip_reason(self, ctx: FitContext) -> str | None:
        """A message when the lens has no co-design adversary (a fixed lens), else None."""
        if ctx.adversary is None:
            name = getattr(getattr(ctx.lens, "spec", None), "name", "this lens")
            return f"{name} was not co-designed with a deblurring adversary (FitContext.adversary is None)"
        return None

    def fit(self, ctx: FitContext) -> FitReport:
        """Take a frozen copy of ``ctx.adversary``; a later step of co-design cannot change the
        attacker being scored."""
        adversary: nn.Module | None = ctx.adversary
        assert adversary is not None  # checked by `requires`
        network = copy.deepcopy(adversary).requires_grad_(False).eval()
        self._network = type(adversary).__name__
        self.engine = InferenceEngine(network, self.backend, fallback=True)
        return FitReport()

    def restore(self, sensor: Tensor) -> Tensor:
        """Scene estimate: (B, 3, H, W) in [0, 1] -> (B, 3, H, W) in [0, 1]."""
        if self.engine is None:
            raise RuntimeError(f"{self.name}: call fit(ctx) with a co-designed lens before restore()")
        return self.engine(sensor).clamp(0.0, 1.0)

    def describe(self) -> dict[str, Any]:
        """Configuration: backend option and the adversary's class name."""
        return {**super().describe(), "backend": self.backend, "network": self._network}
