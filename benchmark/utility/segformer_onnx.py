"""SegFormer evaluation inference through ONNX Runtime, exported once per set of weights.

On the 2-core CPU, ONNX Runtime runs SegFormer-B0's sliding-window inference (the quick profile's
256 x 256 windows, 8 at a time, 2 threads) 1.5-1.9x as fast as eager torch (1.86x in
tests/benchmarks/test_segformer_speed.py, which asserts that it wins), so evaluation on the CPU
uses it by default. The backend is fixed, not timed per run as the restorers' ``"auto"`` is, so the same
weights on the same machine always give the same predictions (the two backends differ by ~1e-7 in
the logits, which can flip an exact tie). The ONNX graph is cached under the run's cache folder,
verified by its checksum, keyed by the sha256 of the weights and the versions that shape the graph;
if the export fails the evaluation runs with torch and logs why.
"""

from __future__ import annotations

import hashlib
import logging
from collections import OrderedDict
from importlib.metadata import version
from pathlib import Path
from typing import Any

import torch
from torch import Tensor, nn

from attacks.onnx_backend import InferenceEngine, check_backend, export_onnx
from benchmark.cache import ArtifactCache
from benchmark.utility.segformer import segment_logits

__all__ = ["SEGMENTATION_BACKEND", "SegformerLogits", "segformer_engine", "weights_sha256"]

log = logging.getLogger(__name__)

SEGMENTATION_BACKEND = "onnx"
_GRAPH = "segment_logits/v1"  # bump when SegformerLogits changes what the exported graph computes
_ENGINES: OrderedDict[tuple[str, str, int], InferenceEngine] = OrderedDict()
_MAX_ENGINES = 4  # a task holds at most the clean net and the lens's own net
_UNSPLIT = 2**62  # the callers batch the windows themselves (the profile's batch size)


class SegformerLogits(nn.Module):
    """Images (B, 3, H, W) in [0, 1] -> full-size logits (B, num_labels, H, W): ``segment_logits``
    as one module, so that the normalisation and the upsampling are in the exported graph."""

    def __init__(self, net: nn.Module) -> None:
        super().__init__()
        self.net: Any = net  # a SegformerForSemanticSegmentation; typed loosely as callers hold an nn.Module

    def forward(self, images: Tensor) -> Tensor:
        return segment_logits(self.net, images)


def weights_sha256(net: nn.Module) -> str:
    """sha256 over the names, dtypes, shapes and values of ``net``'s state dict."""
    h = hashlib.sha256()
    for name, tensor in net.state_dict().items():
        t = tensor.detach().cpu().contiguous()
        h.update(f"{name}:{t.dtype}:{tuple(t.shape)};".encode())
        h.update(t.reshape(-1).view(torch.uint8).numpy().tobytes())
    return h.hexdigest()


def segformer_engine(net: nn.Module, cache_dir: Path, window: tuple[int, int],
                     backend: str = SEGMENTATION_BACKEND) -> InferenceEngine:
    """The inference engine of ``net`` (a SegFormer in eval mode) for full-size logits.

    Args:
        net: The SegFormer; on a device other than the CPU it always runs with torch.
        cache_dir: The run's cache folder; the ONNX graph lives under ``<cache_dir>/onnx/``.
        window: (H, W) of the sliding window, the size the graph is traced at (its axes are dynamic).
        backend: "onnx" (default on the CPU: falls back to torch with a logged reason if the export
            fails), "torch", or "auto" (times both on the first window batch and keeps the faster).

    Returns:
        An engine, images (B, 3, H, W) in [0, 1] -> logits (B, num_labels, H, W); ``describe()``
        says which backend runs. ONNX Runtime engines are reused within the process for the same weights.
    """
    check_backend(backend)
    if any(p.device.type != "cpu" for p in net.parameters()):
        return InferenceEngine(SegformerLogits(net), "torch", batch_pixels=_UNSPLIT)
    digest = weights_sha256(net)
    key = (digest, backend, torch.get_num_threads())
    if key in _ENGINES:
        _ENGINES.move_to_end(key)
        return _ENGINES[key]
    model = SegformerLogits(net).eval()
    store = ArtifactCache(Path(cache_dir) / "onnx", suffix=".onnx")
    artifact = {"weights_sha256": digest, "graph": _GRAPH, "torch": torch.__version__,
                "transformers": version("transformers")}

    def exporter() -> bytes:
        data = store.load("segformer", artifact)
        if data is None:
            data = export_onnx(model, torch.rand(1, 3, *window))
            store.save("segformer", artifact, data)
            log.info("exported SegFormer (weights %s) to ONNX: %s", digest[:12], store.path("segformer", artifact))
        return data

    engine = InferenceEngine(model, backend, exporter=exporter, batch_pixels=_UNSPLIT, fallback=True)
    if engine.backend == "onnx":  # the session holds its own copy of the weights; torch would share `net`
        _ENGINES[key] = engine
        while len(_ENGINES) > _MAX_ENGINES:
            _ENGINES.popitem(last=False)
    return engine
