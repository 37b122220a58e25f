"""SegFormer-B0 evaluation inference, torch against ONNX Runtime, as the quick evaluation runs it.

Run with `pytest tests/benchmarks/test_segformer_speed.py --benchmark-only`. The shipped quick clean
net segments 8 images (the profile's batch) by sliding 256 x 256 windows (the quick window, stride
192) with 2 threads, through `predict` with the torch path (the code before ONNX Runtime) and with
the ONNX Runtime engine, alternating rounds so both see the same load on the shared machine.
Target (issue 17): ONNX Runtime faster than torch, with the same predictions; the ratio is stored in
`extra_info` and is why `benchmark.utility.segformer_onnx` uses ONNX Runtime on the CPU.
"""

from __future__ import annotations

import time

import torch

from benchmark.profiles import PROFILES
from benchmark.utility.clean import load_verified, shipped_for
from benchmark.utility.scoring import predict, window_for
from benchmark.utility.segformer_onnx import segformer_engine

ROUNDS = 3
THREADS = 2


def test_segformer_b0_sliding_window_torch_vs_onnx(benchmark, tmp_path):
    profile = PROFILES["quick"]
    weights = shipped_for(profile)
    assert weights is not None, "no shipped quick SegFormer weights"
    net = load_verified(weights, profile.utility_model)
    window, stride = window_for(profile.image_size, profile.train_crop)
    # The quick batch and window; 256 x 512 images hold 3 window positions (a 512 x 1024 scene has 15).
    images = torch.rand(profile.batch_size, 3, 256, 512, generator=torch.Generator().manual_seed(0))
    threads = torch.get_num_threads()
    torch.set_num_threads(THREADS)
    try:
        engine = segformer_engine(net, tmp_path, window)
        assert engine.backend == "onnx"
        runs = {"torch": lambda: predict(net, images, window, stride, profile.batch_size),
                "onnx": lambda: predict(net, images, window, stride, profile.batch_size, logits=engine)}
        preds = {name: run() for name, run in runs.items()}  # warm-up
        seconds: dict[str, list[float]] = {name: [] for name in runs}
        for _ in range(ROUNDS):
            for name, run in runs.items():
                t0 = time.perf_counter()
                run()
                seconds[name].append(time.perf_counter() - t0)
        benchmark.pedantic(runs["onnx"], rounds=1, iterations=1, warmup_rounds=0)
    finally:
        torch.set_num_threads(threads)
    n_windows = images.shape[0] * 3
    speedup = min(seconds["torch"]) / min(seconds["onnx"])
    benchmark.extra_info.update({"torch_windows_per_s": n_windows / min(seconds["torch"]),
                                 "onnx_windows_per_s": n_windows / min(seconds["onnx"]),
                                 "onnx_speedup": speedup, "threads": THREADS, "window": list(window)})
    assert torch.equal(preds["onnx"], preds["torch"])
    assert speedup > 1.0, f"ONNX Runtime {speedup:.2f}x torch on SegFormer-B0 windows; use torch on this machine"
