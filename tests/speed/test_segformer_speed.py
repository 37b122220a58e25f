"""SegFormer-B0 evaluation inference, torch against ONNX Runtime, as the quick evaluation runs it.

Run with `pytest tests/speed/test_segformer_speed.py --benchmark-only`. The shipped quick clean
net segments 8 images (the profile's batch) by sliding 256 x 256 windows (the quick window, stride
192) with 2 threads, through `predict` with the torch path (the code before ONNX Runtime) and with
the ONNX Runtime engine, alternating rounds so both see the same load on the shared machine.
Target: ONNX Runtime faster than torch, with the same predictions; the ratio is stored in
`extra_info` and is why `benchmark.codesign.utility.segformer_onnx` uses ONNX Runtime on the CPU.
"""

from __future__ import annotations

import torch

from attacks.backends.onnx_runtime import OnnxModel, export_onnx
from benchmark.store.profiles import PROFILES
from benchmark.codesign.utility.clean import load_verified, shipped_for
from benchmark.codesign.utility.scoring import predict, window_for
from benchmark.codesign.utility.segformer_onnx import FoldedSegformerLogits, segformer_engine

from alternating import alternate

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
        preds, seconds = alternate(runs, ROUNDS)
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


def test_segformer_engine_keeps_its_arena_between_runs(benchmark, tmp_path):
    """The engine's ONNX Runtime session keeps its memory arena from run to run (segformer_engine):
    against a session that gives it back after every run (as the restorers' do), on the quick batch
    of 8 full 512 x 1024 scenes (15 window batches each), alternating rounds. Target: kept <= 0.9x
    the time of given back, with equal predictions."""

    profile = PROFILES["quick"]
    weights = shipped_for(profile)
    assert weights is not None, "no shipped quick SegFormer weights"
    net = load_verified(weights, profile.utility_model)
    window, stride = window_for(profile.image_size, profile.train_crop)
    images = torch.rand(profile.batch_size, 3, *profile.image_size, generator=torch.Generator().manual_seed(0))
    threads = torch.get_num_threads()
    torch.set_num_threads(THREADS)
    try:
        kept = segformer_engine(net, tmp_path, window)
        assert kept.backend == "onnx"
        given_back = OnnxModel(export_onnx(FoldedSegformerLogits(net).eval(), torch.rand(1, 3, *window)),
                               shrink_arena=True)
        runs = {"kept": lambda: predict(net, images, window, stride, profile.batch_size, logits=kept),
                "given_back": lambda: predict(net, images, window, stride, profile.batch_size, logits=given_back)}
        preds, seconds = alternate(runs, ROUNDS)
        benchmark.pedantic(runs["kept"], rounds=1, iterations=1, warmup_rounds=0)
    finally:
        torch.set_num_threads(threads)
    ratio = min(seconds["kept"]) / min(seconds["given_back"])
    benchmark.extra_info.update({"kept_s": min(seconds["kept"]), "given_back_s": min(seconds["given_back"]),
                                 "ratio_kept_over_given_back": ratio, "threads": THREADS})
    assert torch.equal(preds["kept"], preds["given_back"])
    assert ratio <= 0.9, f"keeping the arena took {ratio:.2f}x the time of giving it back after every run"
