"""SegFormer evaluation inference through ONNX Runtime, exported once per set of weights.

On the CPU, ONNX Runtime runs SegFormer-B0's sliding-window inference (the quick profile's 256 x 256
windows, 8 at a time) faster than eager torch (tests/speed/test_segformer_speed.py asserts that it
wins; docs/modelling.md, "Speed of the evaluation"; docs/history.md), so evaluation on the CPU
uses it by default. The backend is fixed, not timed per run as the restorers' ``"auto"`` is, so the same
weights on the same machine always give the same predictions (the two backends differ by ~1e-7 in
the logits, ~1e-5 with the folded head below, which can flip a near tie; lpdr's vehicle boxes and reads on
the 201 quick plate windows of lenses gp and ideal, seed 0, are the same through both graphs). The ONNX graph is cached under the run's cache folder,
verified by its checksum, keyed by the sha256 of the weights and the versions that shape the graph;
if the export fails the evaluation runs with torch and logs why.

The exported graph is ``FoldedSegformerLogits``: the decode head's 1x1 fuse convolution (1024 -> 256
channels at a quarter of the input resolution, about three quarters of B0's multiply-adds at 256 x 256)
and its batch norm folded into each stage's projection, which is exact algebra (bilinear upsampling is
linear and keeps constants), so the logits agree with ``segment_logits`` to float rounding (~1e-5)
while ONNX Runtime runs the folded graph faster than the unfolded one (docs/history.md; the lpdr
vehicle stage is timed by tests/speed/test_lpdr_chain_speed.py).
"""

from __future__ import annotations

import hashlib
import logging
from collections import OrderedDict
from importlib.metadata import version
from pathlib import Path
from typing import Any

import torch
import torch.nn.functional as F
from torch import Tensor, nn

from attacks.backends.onnx_runtime import InferenceEngine, check_backend, export_onnx
from benchmark.store.cache import ArtifactCache
from benchmark.codesign.utility.segformer import IMAGENET_MEAN, IMAGENET_STD, segment_logits

__all__ = ["SEGMENTATION_BACKEND", "FoldedSegformerLogits", "SegformerLogits", "segformer_engine", "weights_sha256"]

log = logging.getLogger(__name__)

SEGMENTATION_BACKEND = "onnx"
_GRAPH = "segment_logits/v2-folded"  # bump when SegformerLogits changes what the exported graph computes
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


class FoldedSegformerLogits(nn.Module):
    """``SegformerLogits`` of a SegFormer in eval mode, with its decode head folded for inference.

    SegFormer's head projects each encoder stage ``i`` to 256 channels (``P_i``), upsamples it to a
    quarter of the input size, concatenates the four and fuses them with a 1x1 convolution ``F`` and a
    batch norm (scale ``s``, shift ``t``). As bilinear upsampling is linear and reproduces constants,
    that is ``sum_i up(s * F_i P_i x_i) + s * (sum_i F_i b_i - mean) + beta``: one small 1x1 convolution
    per stage at the stage's own resolution (the products are taken in float64 once, here) and no
    1024-channel tensor. The weights are a snapshot of ``net`` when this is built.

    Raises:
        ValueError: ``net``'s head is not SegFormer's all-MLP head on 4-D stage outputs.
    """

    def __init__(self, net: nn.Module) -> None:
        super().__init__()
        model: Any = net
        head, config = model.decode_head, model.config
        if not getattr(config, "reshape_last_stage", True) or head.linear_fuse.bias is not None:
            raise ValueError("FoldedSegformerLogits needs SegFormer's all-MLP decode head on 4-D stage outputs "
                             "(config.reshape_last_stage True, linear_fuse without bias)")
        self.encoder = model.segformer
        hidden, stages = config.decoder_hidden_size, len(head.linear_projections)
        fuse = head.linear_fuse.weight.detach().double()[:, :, 0, 0]
        norm = head.batch_norm
        scale = norm.weight.detach().double() / torch.sqrt(norm.running_var.double() + norm.eps)
        shift = norm.bias.detach().double() - scale * norm.running_mean.double()
        self.projections = nn.ModuleList()
        for i, mlp in enumerate(head.linear_projections):
            # The head concatenates the stages last first (``all_hidden_states[::-1]``).
            part = fuse[:, (stages - 1 - i) * hidden:(stages - i) * hidden]
            conv = nn.Conv2d(mlp.proj.in_features, hidden, kernel_size=1, bias=False)
            weight = scale[:, None] * (part @ mlp.proj.weight.detach().double())
            conv.weight.data = weight[:, :, None, None].float()
            shift = shift + scale * (part @ mlp.proj.bias.detach().double())
            self.projections.append(conv)
        self.register_buffer("shift", shift.float().view(1, -1, 1, 1))
        self.classifier = head.classifier
        self.register_buffer("mean", torch.tensor(IMAGENET_MEAN).view(1, 3, 1, 1))
        self.register_buffer("std", torch.tensor(IMAGENET_STD).view(1, 3, 1, 1))
        self.shift: Tensor
        self.mean: Tensor
        self.std: Tensor

    def forward(self, images: Tensor) -> Tensor:
        """Images (B, 3, H, W) in [0, 1] -> logits (B, num_labels, H, W), as ``segment_logits``."""
        if images.dim() != 4 or images.shape[1] != 3:
            raise ValueError(f"images must be (B, 3, H, W) RGB in [0, 1], got shape {tuple(images.shape)}")
        states = self.encoder((images - self.mean) / self.std, output_hidden_states=True).hidden_states
        size = states[0].shape[2:]
        fused = self.shift
        for state, projection in zip(states, self.projections):
            projected = projection(state)
            if projected.shape[2:] != size:
                projected = F.interpolate(projected, size=size, mode="bilinear", align_corners=False)
            fused = fused + projected
        logits = self.classifier(torch.relu(fused))
        return F.interpolate(logits, size=images.shape[-2:], mode="bilinear", align_corners=False)


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
            data = export_onnx(FoldedSegformerLogits(model.net).eval(), torch.rand(1, 3, *window))
            store.save("segformer", artifact, data)
            log.info("exported SegFormer (weights %s) to ONNX: %s", digest[:12], store.path("segformer", artifact))
        return data

    # torch runs the head as trained (the reference); ONNX Runtime the folded head (same logits to ~1e-5).
    # The arena is kept between runs: every run is at most a batch of sliding windows, so it stays
    # bounded (about 200 MiB more resident), while giving it back after each run and faulting it in
    # again made the quick sharp-scene scoring slower (docs/history.md).
    engine = InferenceEngine(model, backend, exporter=exporter, batch_pixels=_UNSPLIT, fallback=True,
                             shrink_arena=False)
    if engine.backend == "onnx":  # the session holds its own copy of the weights; torch would share `net`
        _ENGINES[key] = engine
        while len(_ENGINES) > _MAX_ENGINES:
            _ENGINES.popitem(last=False)
    return engine
