"""The recognizer's convolutions through ONNX Runtime (attacks/plates/ocr_onnx.py): equal to torch to float
rounding, independent of the batch, the same confident plate reads, and torch when the export fails."""

from __future__ import annotations

import logging

import numpy as np
import torch

import attacks
from attacks.plates import ocr as plate_ocr
from attacks.plates import ocr_onnx
from attacks.plates.easyocr_models import load_easyocr
from benchmark.scenes import load_scenes


def _model():
    model = load_easyocr(False).recognizer
    return getattr(model, "module", model)


def test_onnx_features_agree_with_torch_and_do_not_depend_on_the_batch():
    model = _model()
    features = ocr_onnx.feature_extractor(model, "onnx")
    assert features is not model.FeatureExtraction  # a session, not the torch module
    x = torch.rand(4, 1, 64, 192, generator=torch.Generator().manual_seed(0)) * 2 - 1
    together = features(x)
    alone = torch.cat([features(x[i:i + 1]) for i in range(4)])
    with torch.no_grad():
        reference = model.FeatureExtraction(x)
    assert together.shape == reference.shape
    assert torch.equal(together, alone)
    assert float((together - reference).abs().max()) <= 1e-4 * float(reference.abs().max())
    assert ocr_onnx.feature_extractor(model, "onnx") is features  # one session per recognizer


def test_the_same_confident_reads_with_either_backend():
    scenes = load_scenes("synthetic", "val", 6, (512, 1024), 0)
    images = torch.from_numpy(np.stack([s.image for s in scenes])).permute(0, 3, 1, 2).float()
    blurred = torch.nn.functional.avg_pool2d(images, 5, 1, 2, count_include_pad=False)
    reader = attacks.load("lpdr-oracle")
    hints = attacks.ReadHints(vehicle_boxes=[[v.box_xyxy for v in s.vehicles] for s in scenes])
    rows = {}
    for im in (images, blurred):
        reader.read(im, hints)
        rgb = (im.clamp(0, 1) * 255).round().byte().permute(0, 2, 3, 1).numpy()
        for image, trace in zip(rgb, reader.last_trace):
            for _, (x0, y0, x1, y1) in trace.plates:
                rows[len(rows)] = plate_ocr.prepare_crop(image[y0:y1, x0:x1])
    ocr = load_easyocr(False)
    torch_reads = plate_ocr.recognize_rows(ocr, rows, "torch")
    onnx_reads = plate_ocr.recognize_rows(ocr, rows, "onnx")
    confident = [k for k, (_, score) in torch_reads.items() if score >= 0.5]
    assert len(rows) >= 20 and len(confident) >= 4  # real plates were read
    assert set(onnx_reads) == set(torch_reads)
    assert all(onnx_reads[k][0] == torch_reads[k][0] for k in confident)
    assert max(abs(onnx_reads[k][1] - torch_reads[k][1]) for k in confident) < 0.01


def test_a_failed_export_falls_back_to_torch(monkeypatch, caplog):
    model = _model()

    def fail(_):
        raise RuntimeError("no exporter here")
    monkeypatch.setattr(ocr_onnx, "_export", fail)
    monkeypatch.setattr(ocr_onnx, "_SESSIONS", {})
    with caplog.at_level(logging.WARNING, logger="attacks.plates.ocr_onnx"):
        assert ocr_onnx.feature_extractor(model, "onnx") is model.FeatureExtraction
    assert "no exporter here" in caplog.text
    assert ocr_onnx.feature_extractor(model, "torch") is model.FeatureExtraction
