"""The recognizer's convolutional feature extractor through ONNX Runtime on the CPU.

EasyOCR's english_g2 spends most of a plate read in its VGG feature extractor (measured on quick plate
windows, lpdr-oracle, 2 threads: 39.5 s of 41.4 s in the convolutions, 2 s in the per-crop BiLSTM
tail), and ONNX Runtime runs those convolutions in 0.4-0.6x torch's time on this 2-core machine
(tests/benchmarks/test_ocr_features_speed.py). Only the convolutions move: the dynamically quantized
tail stays in torch (``attacks.plates.ocr.SharedFeatures``). The two backends agree to float rounding
(about 1e-6 of features of magnitude 4); ``tests/attacks/test_ocr_onnx.py`` checks the agreement, that a
crop's features do not depend on its batch, and that plates read alike.

One session per recognizer per process, exported on first use (about 1 s) and never written to disk.
If the export or ONNX Runtime fails, torch is used and the reason logged.
"""

from __future__ import annotations

import logging
from typing import Any

import torch
from torch import nn

from attacks.onnx_backend import OnnxModel, export_onnx

__all__ = ["feature_extractor"]

log = logging.getLogger(__name__)

_SESSIONS: dict[int, tuple[nn.Module, OnnxModel | None]] = {}


def _export(features: nn.Module) -> bytes:
    axes_in = {0: "batch", 3: "width"}
    axes_out = {0: "batch", 3: "columns"}
    return export_onnx(features.eval(), torch.rand(1, 1, 64, 256), axes=(axes_in, axes_out))


def feature_extractor(model: Any, backend: str = "onnx") -> Any:
    """A callable (B, 1, 64, W) -> (B, 256, 1, W') computing ``model.FeatureExtraction``.

    ``backend`` "onnx" (on the CPU; falls back to torch if the export fails) or "torch".
    """
    features: nn.Module = model.FeatureExtraction
    on_cpu = all(p.device.type == "cpu" for p in features.parameters())
    if backend != "onnx" or not on_cpu:
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
    return features if session is None else session
