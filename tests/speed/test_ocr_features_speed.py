"""Plate OCR with the recognizer's convolutions in ONNX Runtime against torch, and the backend "auto" chooses
on this machine, as ratios in one run.

Run with `pytest tests/speed/test_ocr_features_speed.py --benchmark-only`: asserted then that the chosen
path ("auto", the default) is no slower than the faster of the two (within AUTO_MARGIN, fastest of ROUNDS
interleaved rounds, on THREADS threads), on any machine; ONNX Runtime against torch alone is recorded, not
asserted (0.4-0.6x on an AVX2 machine, not faster on an AVX-512 one). Without --benchmark-only the test only
checks that both read alike (plate_reference.assert_backends_read_alike). The crops are lpdr-oracle's plate
crops of FRAMES quick val frames, sharp and box-blurred (blurred crops take EasyOCR's second, contrast-adjusted
pass, as a lens's do). `extra_info` holds the seconds per crop of each, the ratios, the choice, the threads
and the load.
"""

from __future__ import annotations

import os
import time

import torch

from attacks.readers.plates import ocr as plate_ocr
from attacks.readers.plates import ocr_onnx
from attacks.readers.plates.easyocr_models import load_easyocr
from plate_reference import assert_backends_read_alike, plate_crop_rows  # tests/plate_reference.py

AUTO_MARGIN = 1.1
ROUNDS = 2
THREADS = 2
FRAMES = 8


def test_ocr_onnx_features_vs_torch(benchmark, request):
    ocr = load_easyocr(False)
    rows = plate_crop_rows(FRAMES)
    threads = torch.get_num_threads()
    torch.set_num_threads(THREADS)
    try:
        backends = ("torch", "onnx", "auto")
        reads = {b: plate_ocr.recognize_rows(ocr, rows, b) for b in backends}  # warm-up (export, probe) too
        seconds: dict[str, list[float]] = {b: [] for b in backends}
        for _ in range(ROUNDS):  # interleaved, so that a change of machine load hits all
            for backend in backends:
                t0 = time.perf_counter()
                plate_ocr.recognize_rows(ocr, rows, backend)
                seconds[backend].append(time.perf_counter() - t0)
        benchmark.pedantic(lambda: plate_ocr.recognize_rows(ocr, rows, "auto"), rounds=1, iterations=1)
    finally:
        torch.set_num_threads(threads)
    assert any(score >= 0.8 for _, score in reads["torch"].values())  # the comparison covered confident reads
    assert_backends_read_alike(reads["torch"], reads["onnx"])
    assert reads["auto"] == reads[ocr_onnx.choices()["backend"]]  # auto reads as the backend it chose
    fastest = min(min(seconds["onnx"]), min(seconds["torch"]))
    auto_ratio = min(seconds["auto"]) / fastest
    benchmark.extra_info.update({"crops": len(rows), "onnx_over_torch": min(seconds["onnx"]) / min(seconds["torch"]),
                                 "auto_over_fastest": auto_ratio, "chosen": ocr_onnx.choices(), "threads": THREADS,
                                 "load_average": list(os.getloadavg()),
                                 **{f"{b}_s_per_crop": min(s) / len(rows) for b, s in seconds.items()}})
    if request.config.getoption("benchmark_only"):
        assert auto_ratio <= AUTO_MARGIN, benchmark.extra_info
