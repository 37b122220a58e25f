"""The recognizer's convolutions through ONNX Runtime (attacks/readers/plates/ocr_onnx.py): equal to torch to float
rounding, independent of the batch, the same confident plate reads, and torch when the export fails."""

from __future__ import annotations

import logging

import pytest
import torch

from attacks.readers.plates import ocr as plate_ocr
from attacks.readers.plates import ocr_onnx
from attacks.readers.plates.easyocr_models import load_easyocr
from plate_reference import assert_backends_read_alike, plate_crop_rows  # tests/plate_reference.py


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


@pytest.mark.slow
def test_the_same_confident_reads_with_either_backend():
    """Reads agree except where the recognizer is unsure. The quantized BiLSTM tail scales its
    activations by their range and rounds them to 8 bits, so features that differ by 1e-6 of their
    scale can move a crop's confidence by a few hundredths and flip a character it was unsure of.
    Measured on a CPU with AVX2, no AVX-512 (2026-11-27, features within 1.1e-6): of 46 crops one read 'MQ8362F' at
    0.556 with torch and 'MQ836ZF' at 0.578 with ONNX Runtime, one kept its text at 0.837 vs 0.869, the
    rest agreed within 0.01; on the machines before, every read of confidence >= 0.5 agreed."""
    rows = plate_crop_rows(6)
    ocr = load_easyocr(False)
    torch_reads = plate_ocr.recognize_rows(ocr, rows, "torch")
    onnx_reads = plate_ocr.recognize_rows(ocr, rows, "onnx")
    assert len(rows) >= 20 and sum(score >= 0.5 for _, score in torch_reads.values()) >= 4  # real plates were read
    assert_backends_read_alike(torch_reads, onnx_reads)


def test_a_failed_export_falls_back_to_torch(monkeypatch, caplog):
    model = _model()

    def fail(_):
        raise RuntimeError("no exporter here")
    monkeypatch.setattr(ocr_onnx, "_export", fail)
    monkeypatch.setattr(ocr_onnx, "_SESSIONS", {})
    with caplog.at_level(logging.WARNING, logger="attacks.readers.plates.ocr_onnx"):
        assert ocr_onnx.feature_extractor(model, "onnx") is model.FeatureExtraction
    assert "no exporter here" in caplog.text
    assert ocr_onnx.feature_extractor(model, "torch") is model.FeatureExtraction


DELAY_S = 1.0


@pytest.mark.slow
def test_auto_keeps_whichever_backend_the_probe_times_faster(monkeypatch):
    # An injected delay (DELAY_S, more than either takes here) in one backend: "auto" keeps the other, decides once, and says what it timed.
    from types import SimpleNamespace
    shared = _model()  # EasyOCR's recognizer, shared by the tests: never patched itself
    torch_features = shared.FeatureExtraction
    session = ocr_onnx.feature_extractor(shared, "onnx")
    for slow in ("onnx", "torch"):
        monkeypatch.setattr(ocr_onnx, "_CHOSEN", {})
        if slow == "onnx":
            model = shared
            monkeypatch.setitem(ocr_onnx._SESSIONS, id(torch_features), (torch_features, _Delayed(session)))
        else:  # a slow torch module of its own (its session is exported from it: the sleep is not traced)
            model = SimpleNamespace(FeatureExtraction=_Delayed(torch_features))
        chosen = ocr_onnx.feature_extractor(model, "auto")
        fast = "torch" if slow == "onnx" else "onnx"
        assert ocr_onnx.choices()["backend"] == fast
        probe = ocr_onnx.choices()["probe_s"]
        assert probe[slow] >= DELAY_S and probe[slow] > probe[fast]  # the fast side may take 0.6 s under load
        assert (chosen is model.FeatureExtraction) == (fast == "torch")
        assert ocr_onnx.feature_extractor(model, "auto") is chosen  # decided once per process
        monkeypatch.undo()


class _Delayed(torch.nn.Module):
    """A feature extractor slowed by DELAY_S a call."""

    def __init__(self, inner):
        super().__init__()
        self.inner = inner

    def forward(self, x):
        import time
        time.sleep(DELAY_S)
        return self.inner(x)
