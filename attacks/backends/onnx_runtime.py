"""Fast inference for image networks: ONNX Runtime on the CPU, with the torch path kept.

``torch.onnx.export(..., dynamo=False)`` (the TorchScript exporter) is used: with torch 2.14
the default dynamo exporter needs ``onnxscript``, which is not installed, while the TorchScript
exporter works offline and exports NAFNet, RED10 and SegFormer with dynamic batch and image size.
On 2 CPU cores ONNX Runtime runs the quick-profile NAFNet 1.8x (RED10 1.7x) as fast as eager torch
at 512 x 1024 (tests/speed/test_restorer_speed.py; 3.2x and 3.9x with the machine loaded
8-fold), and SegFormer-B0 1.9x on the evaluation's 256 x 256 windows in batches of 8
(tests/speed/test_segformer_speed.py), but that is a property of the machine, the network
and the image size, so ``backend="auto"`` measures both once and keeps the faster.
"""

from __future__ import annotations

import io
import logging
import time
import warnings
from collections.abc import Callable, Iterator
from typing import Any, Literal

import torch
from torch import Tensor, nn

__all__ = ["BACKENDS", "DEFAULT_BATCH_PIXELS", "Backend", "InferenceEngine", "OnnxModel", "check_backend",
           "export_onnx"]

Backend = Literal["auto", "torch", "onnx"]
BACKENDS: tuple[str, ...] = ("auto", "torch", "onnx")
_OPSET = 17
# Pixels per network call: 2 images of 512 x 1024, the most the evaluation hands a restorer in one call
# (benchmark.runner.evaluation.RESTORE_PIXELS_PER_BATCH), so a restorer called directly batches as in a run.
# Two a call are at least as fast as one on the machines measured, where four were not on every one, and
# need half the activations' memory of four (tests/speed/test_restorer_speed.py; docs/history.md).
DEFAULT_BATCH_PIXELS = 2 * 512 * 1024

log = logging.getLogger(__name__)


def check_backend(backend: str) -> str:
    """Return ``backend`` if it is one of ``BACKENDS``, else raise ValueError naming the valid ones."""
    if backend not in BACKENDS:
        raise ValueError(f"backend {backend!r} is not one of {BACKENDS}")
    return backend


def export_onnx(model: nn.Module, example: Tensor,
                axes: tuple[dict[int, str], dict[int, str]] | None = None) -> bytes:
    """Serialize ``model`` (image (B, C, H, W) -> map (B, C', H, W)) to ONNX with dynamic B, H, W.

    Args:
        model: A module in eval mode, on the CPU, whose output is one (B, C', H, W) tensor at the
            input's size (a restored image, or per-pixel logits).
        example: A CPU input of the right channel count used to trace the graph.
        axes: The dynamic axes of the input and of the output, if not B, H and W of both.

    Returns:
        The ONNX model as bytes (opset 17), input "image", output "output".
    """
    buffer = io.BytesIO()
    dynamic = {0: "batch", 2: "height", 3: "width"}
    axes_in, axes_out = axes if axes is not None else (dynamic, dynamic)
    with warnings.catch_warnings():
        # The TorchScript exporter is deprecated in favour of dynamo, which needs onnxscript.
        warnings.simplefilter("ignore")
        torch.onnx.export(
            model, (example,), buffer, dynamo=False, opset_version=_OPSET,
            input_names=["image"], output_names=["output"],
            dynamic_axes={"image": axes_in, "output": axes_out},
        )
    return buffer.getvalue()


class OnnxModel:
    """An ONNX image-to-map model run by ONNX Runtime's CPU provider.

    Args:
        onnx_bytes: Model from ``export_onnx``.
        threads: Intra-op threads; None uses torch's thread count, so both backends compete
            on equal terms.
        shrink_arena: Give the CPU arena's memory back at the end of every run (see below). False
            keeps it for the next run: for a network whose inputs are bounded (SegFormer's sliding
            windows), where re-faulting the arena every run costs more than the memory it holds.
    """

    def __init__(self, onnx_bytes: bytes, threads: int | None = None, shrink_arena: bool = True) -> None:
        import onnxruntime as ort

        options = ort.SessionOptions()
        options.intra_op_num_threads = threads or torch.get_num_threads()
        options.inter_op_num_threads = 1
        options.log_severity_level = 3
        self._session = ort.InferenceSession(onnx_bytes, options, providers=["CPUExecutionProvider"])
        self._input = self._session.get_inputs()[0].name
        # The CPU arena hands each intermediate of a run memory freed by earlier ones; without it, every
        # input size the session has not seen yet (the plate windows come in about 20) mallocs and
        # page-faults each intermediate afresh, several times slower (docs/history.md). Shrinking the
        # arena at the end of every run gives that memory back, so a run holding several restorers'
        # sessions does not keep each one's peak (docs/history.md).
        self._run_options = ort.RunOptions()
        if shrink_arena:
            self._run_options.add_run_config_entry("memory.enable_memory_arena_shrinkage", "cpu:0")

    def __call__(self, x: Tensor) -> Tensor:
        """(B, C, H, W) float32 -> (B, C', H, W) float32 on ``x``'s device."""
        feed = {self._input: x.detach().cpu().float().contiguous().numpy()}
        out = self._session.run(None, feed, self._run_options)[0]
        return torch.from_numpy(out).to(device=x.device, dtype=x.dtype)


class InferenceEngine:
    """Runs an image network through torch or ONNX Runtime, in batches bounded by pixel count.

    Args:
        model: The network, image (B, C, H, W) -> (B, C', H, W); put in eval mode, kept on its device.
        backend: "torch", "onnx" or "auto". "auto" on a CPU exports to ONNX now and, on the
            first call, times both backends on its first image (after a warm-up run each) and
            keeps the faster for good (an engine of the same architecture at the same image
            shape and thread count later in the process reuses those timings); on another device, or if the export fails, it uses torch
            (the reason is logged and kept in ``fallback_reason``).
            The first real batch, not a small probe, decides: which wins moves with the image size,
            the versions and the machine (docs/history.md), so it is timed, not assumed.
        export_hw: (H, W) of the example image the ONNX graph is traced with (axes are dynamic).
        exporter: Returns the ONNX bytes of ``model`` (e.g. from a cache, exporting on a miss);
            default ``export_onnx`` on an example of ``export_hw``.
        batch_pixels: Images per network call are as many as fit in this many pixels (at least
            one), which bounds peak memory at full resolution.
        fallback: With backend "onnx": if the model is not on the CPU or the export fails, use torch
            (logging why) instead of raising. "auto" always falls back.
        shrink_arena: ``OnnxModel``'s: give ONNX Runtime's arena back after every run (default).

    Attributes:
        backend: The backend in use, "torch" or "onnx" ("auto" until the first call decides).
        timings_s: Seconds for the first image per backend, once "auto" has timed them.
        fallback_reason: Why ONNX Runtime is not used although asked for, else None.
    """

    def __init__(self, model: nn.Module, backend: str = "auto", export_hw: tuple[int, int] = (64, 64),
                 exporter: Callable[[], bytes] | None = None, batch_pixels: int = DEFAULT_BATCH_PIXELS,
                 fallback: bool = False, shrink_arena: bool = True) -> None:
        check_backend(backend)
        if batch_pixels < 1:
            raise ValueError(f"batch_pixels must be >= 1, got {batch_pixels}")
        self.model = model.eval()
        self.requested = backend
        self.batch_pixels = batch_pixels
        self.timings_s: dict[str, float] = {}
        self.fallback_reason: str | None = None
        self._onnx: OnnxModel | None = None
        on_cpu = all(p.device.type == "cpu" for p in model.parameters())
        if backend == "onnx" and not on_cpu and not fallback:
            raise ValueError("backend='onnx' runs on the CPU; move the model to the CPU or use 'torch'")
        if backend in ("auto", "onnx") and not on_cpu:
            self.fallback_reason = "the model is not on the CPU"
            backend = "torch"
        if backend == "onnx" or (backend == "auto" and on_cpu):
            export = exporter or (lambda: export_onnx(self.model, torch.rand(1, _channels(model), *export_hw)))
            try:
                self._onnx = OnnxModel(export(), shrink_arena=shrink_arena)
            except Exception as exc:  # noqa: BLE001 - fall back to the always-available path
                if backend == "onnx" and not fallback:
                    raise
                self.fallback_reason = f"ONNX export failed ({type(exc).__name__}: {exc})"
                log.warning("%s; running %s with torch", self.fallback_reason, type(model).__name__)
        self.backend = "torch" if self._onnx is None else backend

    @torch.no_grad()
    def _torch(self, x: Tensor) -> Tensor:
        return self.model(x)

    def _run(self) -> Callable[[Tensor], Tensor]:
        return self._onnx if self.backend == "onnx" and self._onnx is not None else self._torch

    def _choose(self, image: Tensor) -> None:
        key = (_architecture(self.model), tuple(image.shape), torch.get_num_threads())
        if key not in _TIMINGS_S:
            runs = {"torch": self._torch, "onnx": self._onnx}
            _TIMINGS_S[key] = {name: _time(run, image) for name, run in runs.items() if run is not None}
        self.timings_s = dict(_TIMINGS_S[key])
        self.backend = min(self.timings_s, key=self.timings_s.__getitem__)
        log.info("inference backend %s (seconds per image: %s)", self.backend, self.timings_s)

    def batches(self, x: Tensor) -> Iterator[Tensor]:
        """Consecutive slices of ``x`` (B, C, H, W) of at most ``batch_pixels`` pixels (at least one image)."""
        size = max(1, self.batch_pixels // max(1, x.shape[-2] * x.shape[-1]))
        for start in range(0, x.shape[0], size):
            yield x[start:start + size]

    def __call__(self, x: Tensor) -> Tensor:
        """Network output for ``x`` (B, C, H, W), unclamped, on ``x``'s device and dtype."""
        device = next(self.model.parameters()).device
        chunks = [chunk.to(device=device, dtype=torch.float32) for chunk in self.batches(x)]
        if self.backend == "auto" and chunks:
            self._choose(chunks[0][:1])
        run = self._run()
        return torch.cat([run(chunk) for chunk in chunks]).to(device=x.device, dtype=x.dtype)

    def describe(self) -> dict[str, Any]:
        """For a row's settings: requested and used backend, any fallback, the batch bound. Not the
        timings (``timings_s``), which vary run to run and would change the settings' hash."""
        return {"requested": self.requested, "backend": self.backend, "fallback_reason": self.fallback_reason,
                "batch_pixels": self.batch_pixels}


# Seconds per image of each backend, per (architecture, image shape, threads), timed once per process:
# on 2 cores timing the quick NAFNet's two backends costs about 15 s (torch twice at 5-10 s), and
# nafnet-known-pairs and nafnet-generic share the architecture. The weights' values do not change
# the cost of a dense network.
_TIMINGS_S: dict[tuple[Any, ...], dict[str, float]] = {}


def _architecture(model: nn.Module) -> tuple[Any, ...]:
    """The class and every parameter's and buffer's name and shape: what inference cost depends on."""
    tensors = [*model.named_parameters(), *model.named_buffers()]
    return (type(model).__qualname__, repr(model), tuple((name, tuple(t.shape)) for name, t in tensors))


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
