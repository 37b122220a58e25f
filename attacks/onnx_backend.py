"""Fast inference for restorer networks: ONNX Runtime on the CPU, with the torch path kept.

``torch.onnx.export(..., dynamo=False)`` (the TorchScript exporter) is used: with torch 2.14
the default dynamo exporter needs ``onnxscript``, which is not installed, while the TorchScript
exporter works offline and exports NAFNet and RED10 with dynamic batch and image size.
On 2 CPU cores ONNX Runtime runs the quick-profile NAFNet 1.8x (RED10 1.7x) as fast as eager torch
at 512 x 1024 (tests/benchmarks/test_restorer_speed.py), but that is a property of the
machine, the network and the image size, so ``backend="auto"`` measures both once and keeps
the faster.
"""

from __future__ import annotations

import io
import logging
import time
import warnings
from collections.abc import Callable
from typing import Literal

import torch
from torch import Tensor, nn

__all__ = ["BACKENDS", "Backend", "InferenceEngine", "OnnxModel", "check_backend", "export_onnx"]

Backend = Literal["auto", "torch", "onnx"]
BACKENDS: tuple[str, ...] = ("auto", "torch", "onnx")
_OPSET = 17

log = logging.getLogger(__name__)


def check_backend(backend: str) -> str:
    """Return ``backend`` if it is one of ``BACKENDS``, else raise ValueError naming the valid ones."""
    if backend not in BACKENDS:
        raise ValueError(f"backend {backend!r} is not one of {BACKENDS}")
    return backend


def export_onnx(model: nn.Module, example: Tensor) -> bytes:
    """Serialize ``model`` (image (B, C, H, W) -> image) to ONNX with dynamic B, H, W.

    Args:
        model: A module in eval mode, on the CPU.
        example: A CPU input of the right channel count used to trace the graph.

    Returns:
        The ONNX model as bytes (opset 17).
    """
    buffer = io.BytesIO()
    dynamic = {0: "batch", 2: "height", 3: "width"}
    with warnings.catch_warnings():
        # The TorchScript exporter is deprecated in favour of dynamo, which needs onnxscript.
        warnings.simplefilter("ignore")
        torch.onnx.export(
            model, (example,), buffer, dynamo=False, opset_version=_OPSET,
            input_names=["image"], output_names=["restored"],
            dynamic_axes={"image": dynamic, "restored": dynamic},
        )
    return buffer.getvalue()


class OnnxModel:
    """An ONNX image-to-image model run by ONNX Runtime's CPU provider.

    Args:
        onnx_bytes: Model from ``export_onnx``.
        threads: Intra-op threads; None uses torch's thread count, so both backends compete
            on equal terms.
    """

    def __init__(self, onnx_bytes: bytes, threads: int | None = None) -> None:
        import onnxruntime as ort

        options = ort.SessionOptions()
        options.intra_op_num_threads = threads or torch.get_num_threads()
        options.inter_op_num_threads = 1
        options.log_severity_level = 3
        self._session = ort.InferenceSession(onnx_bytes, options, providers=["CPUExecutionProvider"])

    def __call__(self, x: Tensor) -> Tensor:
        """(B, C, H, W) float32 -> (B, C, H, W) float32 on ``x``'s device."""
        out = self._session.run(None, {"image": x.detach().cpu().float().contiguous().numpy()})[0]
        return torch.from_numpy(out).to(device=x.device, dtype=x.dtype)


class InferenceEngine:
    """Runs a restorer network through torch or ONNX Runtime, one image at a time.

    One image at a time bounds peak memory at full resolution (a batch of 8 at 512 x 1024
    would hold several GiB of NAFNet activations).

    Args:
        model: The network, image (B, C, H, W) -> image; put in eval mode, kept on its device.
        backend: "torch", "onnx" or "auto". "auto" on a CPU exports to ONNX now and, on the
            first call, times both backends on the first image (after a warm-up run each) and
            keeps the faster for good; on another device, or if the export fails, it uses torch.
            The first real image, not a small probe, decides: on 2 cores the quick NAFNet ties
            at 256 x 256 but ONNX Runtime is 1.8x faster at 512 x 1024.
        export_hw: (H, W) of the example image the ONNX graph is traced with (axes are dynamic).

    Attributes:
        backend: The backend in use, "torch" or "onnx" ("auto" until the first call decides).
        timings_s: Seconds for the first image per backend, once "auto" has timed them.
    """

    def __init__(self, model: nn.Module, backend: str = "auto", export_hw: tuple[int, int] = (64, 64)) -> None:
        check_backend(backend)
        self.model = model.eval()
        self.timings_s: dict[str, float] = {}
        self._onnx: OnnxModel | None = None
        on_cpu = all(p.device.type == "cpu" for p in model.parameters())
        if backend == "onnx" and not on_cpu:
            raise ValueError("backend='onnx' runs on the CPU; move the model to the CPU or use 'torch'")
        if backend == "onnx" or (backend == "auto" and on_cpu):
            try:
                self._onnx = OnnxModel(export_onnx(self.model, torch.rand(1, _channels(model), *export_hw)))
            except Exception as exc:  # noqa: BLE001 - auto falls back to the always-available path
                if backend == "onnx":
                    raise
                log.warning("ONNX export failed (%s: %s); restoring with torch", type(exc).__name__, exc)
        self.backend = "torch" if self._onnx is None else backend

    @torch.no_grad()
    def _torch(self, x: Tensor) -> Tensor:
        return self.model(x)

    def _run(self) -> Callable[[Tensor], Tensor]:
        return self._onnx if self.backend == "onnx" and self._onnx is not None else self._torch

    def _choose(self, image: Tensor) -> None:
        runs = {"torch": self._torch, "onnx": self._onnx}
        self.timings_s = {name: _time(run, image) for name, run in runs.items() if run is not None}
        self.backend = min(self.timings_s, key=self.timings_s.__getitem__)
        log.info("inference backend %s (seconds per image: %s)", self.backend, self.timings_s)

    def __call__(self, x: Tensor) -> Tensor:
        """Network output for ``x`` (B, C, H, W), unclamped, on ``x``'s device and dtype."""
        device = next(self.model.parameters()).device
        images = [image[None].to(device=device, dtype=torch.float32) for image in x]
        if self.backend == "auto" and images:
            self._choose(images[0])
        run = self._run()
        return torch.cat([run(image) for image in images]).to(device=x.device, dtype=x.dtype)


def _channels(model: nn.Module) -> int:
    first = next(m for m in model.modules() if isinstance(m, nn.Conv2d))
    return first.in_channels


def _time(run: Callable[[Tensor], Tensor], x: Tensor, repeats: int = 1) -> float:
    """Best of ``repeats`` timed calls after one warm-up, in seconds."""
    run(x)
    best = float("inf")
    for _ in range(repeats):
        t0 = time.perf_counter()
        run(x)
        best = min(best, time.perf_counter() - t0)
    return best
