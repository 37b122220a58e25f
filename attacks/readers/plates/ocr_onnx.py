"""The recognizer's convolutional feature extractor through ONNX Runtime on the CPU.

EasyOCR's english_g2 spends most of a plate read in its VGG feature extractor (about 95 % of it on the
quick plate windows, the per-crop BiLSTM tail most of the rest), and ONNX Runtime runs those
convolutions faster than torch on the CPUs measured (tests/speed/test_ocr_features_speed.py;
docs/modelling.md, "OCR convolutions in ONNX Runtime"; docs/history.md). Only the convolutions move: the dynamically quantized
tail stays in torch (``attacks.readers.plates.ocr.SharedFeatures``). The two backends agree to float rounding
(about 1e-6 of features of magnitude 4); ``tests/attacks/readers/test_ocr_onnx.py`` checks the agreement, that a
crop's features do not depend on its batch, and that plates read alike.

One session per recognizer per process, exported on first use (about 1 s) and never written to disk.
If the export or ONNX Runtime fails, torch is used and the reason logged.

Which is faster depends on the machine (the ratio benchmark passed on an AVX2 machine and is asked to hold
on any), so the default backend "auto" decides per machine: on first use in a process it times both on a
fixed probe batch (``PROBE_SHAPE``, fastest of ``PROBE_ROUNDS`` interleaved rounds, about a second) and
keeps the faster, and logs it; ``choices()`` holds the decision and its timings. The readers' ``describe()``
records the policy ("auto"), not the choice: it is made at the first read, after the row settings are taken.
"""

from __future__ import annotations

import logging
import time
from collections.abc import Callable
from typing import Any

import torch
from torch import nn

from attacks.backends.onnx_runtime import OnnxModel, export_onnx

__all__ = ["PROBE_ROUNDS", "PROBE_SHAPE", "choices", "feature_extractor"]

log = logging.getLogger(__name__)

_SESSIONS: dict[int, tuple[nn.Module, OnnxModel | None]] = {}
_CHOSEN: dict[int, tuple[nn.Module, str, dict[str, float]]] = {}  # features id -> (features, backend, seconds)

# The probe: a batch of plate-crop rows as the reader batches them (16 crops padded to 256 columns).
PROBE_SHAPE = (16, 1, 64, 256)
PROBE_ROUNDS = 3


def choices() -> dict[str, Any]:
    """What "auto" chose in this process: {"backend": ..., "probe_s": {backend: seconds}} of the last
    recognizer it decided for (empty before any decision)."""
    if not _CHOSEN:
        return {}
    _, backend, seconds = list(_CHOSEN.values())[-1]
    return {"backend": backend, "probe_s": {k: round(v, 5) for k, v in seconds.items()}}


def _probe(features: nn.Module, session: OnnxModel) -> tuple[str, dict[str, float]]:
    """The faster of torch and ONNX Runtime on ``PROBE_SHAPE`` (fastest of interleaved rounds, after a warm-up)."""
    x = torch.rand(PROBE_SHAPE, generator=torch.Generator().manual_seed(0))
    runs: dict[str, Callable[[torch.Tensor], Any]] = {"torch": features, "onnx": session}
    best = {name: float("inf") for name in runs}
    with torch.no_grad():
        for name, run in runs.items():
            run(x)  # warm-up: first-call allocations, ONNX Runtime's arena
        for _ in range(PROBE_ROUNDS):
            for name, run in runs.items():
                t0 = time.perf_counter()
                run(x)
                best[name] = min(best[name], time.perf_counter() - t0)
    return min(best, key=lambda name: best[name]), best


def _export(features: nn.Module) -> bytes:
    axes_in = {0: "batch", 3: "width"}
    axes_out = {0: "batch", 3: "columns"}
    return export_onnx(features.eval(), torch.rand(1, 1, 64, 256), axes=(axes_in, axes_out))


def feature_extractor(model: Any, backend: str = "auto") -> Any:
    """A callable (B, 1, 64, W) -> (B, 256, 1, W') computing ``model.FeatureExtraction``.

    ``backend`` "onnx" (on the CPU; falls back to torch if the export fails), "torch", or "auto" (on the
    CPU: whichever of the two the probe times faster on this machine, decided once per process).
    """
    if backend not in ("auto", "onnx", "torch"):
        raise ValueError(f"OCR feature backend {backend!r}; valid: auto, onnx, torch")
    features: nn.Module = model.FeatureExtraction
    on_cpu = all(p.device.type == "cpu" for p in features.parameters())
    if backend == "torch" or not on_cpu:
        return features
    key = id(features)
    if key not in _SESSIONS or _SESSIONS[key][0] is not features:
        try:
            session: OnnxModel | None = OnnxModel(_export(features))
        except Exception as exc:  # noqa: BLE001 - torch is always there
            log.warning("OCR features through torch: ONNX export failed (%s: %s)", type(exc).__name__, exc)
            session = None
        _SESSIONS[key] = (features, session)
    session = _SESSIONS[key][1]
    if session is None:
        return features
    if backend == "auto":
        if key not in _CHOSEN or _CHOSEN[key][0] is not features:
            chosen, seconds = _probe(features, session)
            _CHOSEN[key] = (features, chosen, seconds)
            log.info("OCR features through %s on this machine (probe: %s)", chosen,
                     ", ".join(f"{k} {1e3 * v:.1f} ms" for k, v in seconds.items()))
        return features if _CHOSEN[key][1] == "torch" else session
    return session
