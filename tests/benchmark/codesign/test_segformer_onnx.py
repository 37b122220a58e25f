"""SegFormer evaluation through ONNX Runtime: the same logits (1e-4) and the same scores as torch,
the graph exported once per set of weights and cached, torch when the export fails."""

from __future__ import annotations

import logging

import numpy as np
import pytest
import torch

import benchmark.codesign.utility.segformer_onnx as segformer_onnx
from benchmark.store.cache import ArtifactCache
from benchmark.scenes import load_scenes
from benchmark.runner.sensing import to_tensor
from benchmark.codesign.utility.clean import load_verified, shipped_for
from benchmark.store.profiles import PROFILES
from benchmark.codesign.utility.scoring import confusion_matrix, predict, scores
from benchmark.codesign.utility.segformer import build_segformer, segment_logits
from benchmark.codesign.utility.segformer_onnx import segformer_engine, weights_sha256

pytestmark = pytest.mark.slow  # ONNX exports of SegFormer (3-10 s each)


@pytest.fixture(autouse=True)
def fresh_engines(monkeypatch):
    """Each test starts without the process's reused engines."""
    monkeypatch.setattr(segformer_onnx, "_ENGINES", type(segformer_onnx._ENGINES)())


def _net(variant: str, seed: int = 0) -> torch.nn.Module:
    torch.manual_seed(seed)
    return build_segformer(variant).eval()


@pytest.mark.parametrize("variant", ["tiny", "b0"])
def test_onnx_logits_match_torch(tmp_path, variant):
    net = _net(variant)
    engine = segformer_engine(net, tmp_path, window=(64, 64))
    assert engine.backend == "onnx" and engine.describe()["fallback_reason"] is None
    # A batch, and a size the graph was not traced at (its axes are dynamic).
    for shape in [(2, 3, 64, 64), (1, 3, 45, 70)]:
        x = torch.rand(*shape, generator=torch.Generator().manual_seed(1))
        with torch.no_grad():
            reference = segment_logits(net, x)
        assert engine(x).shape == reference.shape
        assert (engine(x) - reference).abs().max() <= 1e-4


def test_scores_of_a_scored_set_are_identical_through_both_backends(tmp_path):
    """The shipped quick clean net on 3 synthetic val scenes: the same predictions, hence the same mIoU."""
    weights = shipped_for(PROFILES["quick"])
    assert weights is not None
    net = load_verified(weights, "b0")
    scenes = load_scenes("synthetic", "val", 3, (128, 256), seed=0)
    images = to_tensor(scenes)
    target = torch.from_numpy(np.stack([s.labels for s in scenes]))
    engine = segformer_engine(net, tmp_path, window=(128, 128))
    assert engine.backend == "onnx"
    preds = {name: predict(net, images, (128, 128), (96, 96), batch_size=2, logits=logits)
             for name, logits in {"torch": None, "onnx": engine}.items()}
    assert torch.equal(preds["onnx"], preds["torch"])
    through = {name: scores(confusion_matrix(pred, target)) for name, pred in preds.items()}
    assert through["torch"]["miou"] > 0.1  # a trained net, not a constant map
    for metric in ("miou", "mean_acc", "overall_acc"):
        assert through["onnx"][metric] == through["torch"][metric]


def test_the_graph_is_exported_once_per_weights_and_a_corrupt_one_is_rebuilt(tmp_path, monkeypatch):
    exports = []
    real_export = segformer_onnx.export_onnx
    monkeypatch.setattr(segformer_onnx, "export_onnx", lambda *a: exports.append(1) or real_export(*a))
    net = _net("tiny")
    segformer_engine(net, tmp_path, window=(32, 32))
    [artifact] = (tmp_path / "onnx" / "segformer").glob("*.onnx")
    segformer_onnx._ENGINES.clear()
    segformer_engine(net, tmp_path, window=(32, 32))  # a new process: read from the cache
    assert len(exports) == 1
    artifact.write_bytes(artifact.read_bytes()[:100])  # truncated: read as absent and exported again
    segformer_onnx._ENGINES.clear()
    x = torch.rand(1, 3, 32, 32)
    with torch.no_grad():
        assert (segformer_engine(net, tmp_path, window=(32, 32))(x) - segment_logits(net, x)).abs().max() <= 1e-4
    assert len(exports) == 2
    other = _net("tiny", seed=1)  # other weights, another graph
    assert weights_sha256(other) != weights_sha256(net)
    segformer_engine(other, tmp_path, window=(32, 32))
    assert len(list((tmp_path / "onnx" / "segformer").glob("*.onnx"))) == 2


def test_a_failed_export_falls_back_to_torch_with_the_reason_logged(tmp_path, monkeypatch, caplog):
    def broken(*_args):
        raise RuntimeError("unsupported operator")

    monkeypatch.setattr(segformer_onnx, "export_onnx", broken)
    net = _net("tiny")
    with caplog.at_level(logging.WARNING):
        engine = segformer_engine(net, tmp_path, window=(32, 32))
    assert engine.backend == "torch"
    assert "unsupported operator" in engine.describe()["fallback_reason"]
    assert "unsupported operator" in caplog.text
    x = torch.rand(1, 3, 32, 32)
    with torch.no_grad():
        assert torch.equal(engine(x), segment_logits(net, x))
    assert not ArtifactCache(tmp_path / "onnx", suffix=".onnx").root.joinpath("segformer").exists()


def test_weights_hash_sees_every_value():
    net = _net("tiny")
    before = weights_sha256(net)
    with torch.no_grad():
        next(net.parameters()).view(-1)[0] += 1e-6
    assert weights_sha256(net) != before
