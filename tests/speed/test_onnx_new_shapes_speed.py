"""ONNX Runtime on input sizes a session has not seen yet: the evaluation's plate windows come in
about 20 sizes, grouped by size, so most of its network calls are a session's first at that size.

Run with `pytest tests/speed/test_onnx_new_shapes_speed.py --benchmark-only`. Baseline: the
session as it was on 2026-11-24 (CPU memory arena off), against ``attacks.backends.onnx_runtime.OnnxModel``
(arena on, shrunk after every run). Each round builds fresh sessions of both, so every call is a
first call at its size; the two alternate round by round, seeing the same load on the shared machine.
"""

from __future__ import annotations

import time

import onnxruntime as ort
import torch

from attacks.backends.onnx_runtime import OnnxModel, export_onnx
from attacks.training.restorer_training import RestorerBudget
from benchmark.store.profiles import PROFILES

# Measured on the shared 2-core machine (load 4-6): 2.5-3.4x per new size at 8 x 256 x 320 and up.
TARGET_SPEEDUP = 1.5
ROUNDS = 2
WINDOW_SHAPES = [(8, 256, 320), (8, 256, 384), (4, 384, 448)]


class _SessionBefore:
    """The ONNX Runtime session before the speed work: no CPU memory arena."""

    def __init__(self, onnx_bytes: bytes) -> None:
        options = ort.SessionOptions()
        options.intra_op_num_threads = torch.get_num_threads()
        options.inter_op_num_threads = 1
        options.log_severity_level = 3
        options.enable_cpu_mem_arena = False
        self._session = ort.InferenceSession(onnx_bytes, options, providers=["CPUExecutionProvider"])

    def __call__(self, x: torch.Tensor) -> torch.Tensor:
        return torch.from_numpy(self._session.run(None, {"image": x.numpy()})[0])


def test_first_calls_at_new_sizes(benchmark):
    model = RestorerBudget.from_profile(PROFILES["quick"]).build_nafnet()
    with torch.no_grad():  # non-zero block scales, as after training
        for name, p in model.named_parameters():
            if name.endswith(("beta", "gamma")):
                p.fill_(0.1)
    onnx = export_onnx(model.eval(), torch.rand(1, 3, 64, 64))
    g = torch.Generator().manual_seed(0)
    windows = [torch.rand(b, 3, h, w, generator=g) for b, h, w in WINDOW_SHAPES]
    seconds: dict[str, list[float]] = {"before": [], "new": []}
    for _ in range(ROUNDS):
        for name, make in (("before", _SessionBefore), ("new", OnnxModel)):
            session = make(onnx)
            t0 = time.perf_counter()
            outputs = [session(x) for x in windows]
            seconds[name].append(time.perf_counter() - t0)
            del session, outputs
    best = {name: min(s) for name, s in seconds.items()}
    benchmark.pedantic(lambda: [OnnxModel(onnx)(x) for x in windows], rounds=1, iterations=1, warmup_rounds=0)
    speedup = best["before"] / best["new"]
    n_images = sum(x.shape[0] for x in windows)
    benchmark.extra_info.update({"before_images_per_s": n_images / best["before"],
                                 "new_images_per_s": n_images / best["new"], "speedup": speedup,
                                 "threads": torch.get_num_threads()})
    assert speedup >= TARGET_SPEEDUP, f"first calls at new sizes: {speedup:.2f}x the session before"
