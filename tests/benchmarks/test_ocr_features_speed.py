"""Plate OCR with the recognizer's convolutions in ONNX Runtime against torch, as a ratio in one run.

Run with `pytest tests/benchmarks/test_ocr_features_speed.py --benchmark-only`: the target (ONNX <= TARGET_RATIO x
torch, fastest of ROUNDS interleaved rounds, on THREADS threads) is asserted then; without --benchmark-only the
test only checks that both read alike (plate_reference.assert_backends_read_alike). The crops are lpdr-oracle's plate crops of FRAMES quick
val frames, sharp and box-blurred (blurred crops take EasyOCR's second, contrast-adjusted pass, as a lens's do).
`extra_info` holds both seconds per crop, the ratio, the threads and the load.
"""

from __future__ import annotations

import os
import time

import torch

from attacks.plates import ocr as plate_ocr
from attacks.plates.easyocr_models import load_easyocr
from plate_reference import assert_backends_read_alike, plate_crop_rows  # tests/plate_reference.py

TARGET_RATIO = 0.8
ROUNDS = 2
THREADS = 2
FRAMES = 8


def test_ocr_onnx_features_vs_torch(benchmark, request):
    ocr = load_easyocr(False)
    rows = plate_crop_rows(FRAMES)
    threads = torch.get_num_threads()
    torch.set_num_threads(THREADS)
    try:
        reads = {b: plate_ocr.recognize_rows(ocr, rows, b) for b in ("torch", "onnx")}  # warm-up (export) too
        seconds: dict[str, list[float]] = {"torch": [], "onnx": []}
        for _ in range(ROUNDS):  # interleaved, so that a change of machine load hits both
            for backend in ("torch", "onnx"):
                t0 = time.perf_counter()
                plate_ocr.recognize_rows(ocr, rows, backend)
                seconds[backend].append(time.perf_counter() - t0)
        benchmark.pedantic(lambda: plate_ocr.recognize_rows(ocr, rows, "onnx"), rounds=1, iterations=1)
    finally:
        torch.set_num_threads(threads)
    assert any(score >= 0.8 for _, score in reads["torch"].values())  # the comparison covered confident reads
    assert_backends_read_alike(reads["torch"], reads["onnx"])
    ratio = min(seconds["onnx"]) / min(seconds["torch"])
    benchmark.extra_info.update({"crops": len(rows), "ratio": ratio, "threads": THREADS,
                                 "load_average": list(os.getloadavg()),
                                 **{f"{b}_s_per_crop": min(s) / len(rows) for b, s in seconds.items()}})
    if request.config.getoption("benchmark_only"):
        assert ratio <= TARGET_RATIO, benchmark.extra_info
