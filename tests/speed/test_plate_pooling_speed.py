"""Reading a chain's plate windows in one `read_batches` call (lpdr recognises the crops of every batch
together) against one `read` call per batch (what the evaluation did before), as a ratio in one run.

The evaluation reads the quick profile's ~200 plate windows in batches of at most 8 windows of one
size: 36 read calls per chain, each recognising a handful of crops, so the recognizer's passes were
small. Pooling changes only how crops are grouped into passes; every crop reads as it would alone
(tests/attacks/readers/test_plate_batching.py), so both ways return the same reads (checked here too).

Run with `pytest tests/speed/test_plate_pooling_speed.py --benchmark-only`: the OCR stage pooled
<= TARGET_RATIO x batch by batch (fastest of ROUNDS interleaved rounds) is asserted then. `extra_info`
holds both ways' OCR seconds, the ratio, the number of read calls and crops, threads and load.
"""

from __future__ import annotations

import os

import torch

import attacks
from attacks.readers.plates.memo import forgetting
from benchmark.runner.evaluation import shape_batches
from benchmark.results.plate_scoring import readable
from benchmark.scenes import load_scene
from benchmark.scenes.windows import plate_windows, window_scene
from benchmark.codesign.utility.scoring import window_for

TARGET_RATIO = 0.85
ROUNDS = 3
N_FRAMES = 60  # about 70 windows in about 25 read calls
BATCH = 8


def _windows() -> tuple[list[torch.Tensor], list]:
    """The sharp plate windows of the first N_FRAMES quick val frames, equal sizes next to each other."""
    min_size = window_for((512, 1024), (128, 128))[0]
    images, scenes = [], []
    for i in range(N_FRAMES):
        frame = load_scene("synthetic", "val", i, (512, 1024), 0)
        for w in plate_windows([frame], readable, min_size):
            scene = window_scene(frame, w)
            scenes.append(scene)
            images.append(torch.from_numpy(scene.image.copy()).permute(2, 0, 1))
    order = sorted(range(len(images)), key=lambda i: (tuple(images[i].shape), i))
    return [images[i] for i in order], [scenes[i] for i in order]


def test_pooled_plate_reading_vs_batch_by_batch(benchmark, request):
    images, scenes = _windows()
    batches = []
    for start, batch in shape_batches(images, BATCH):
        chunk = scenes[start:start + batch.shape[0]]
        batches.append((batch, attacks.ReadHints(vehicle_boxes=[[v.box_xyxy for v in s.vehicles] for s in chunk])))
    reader = attacks.load("lpdr-oracle")
    reader.fit(attacks.FitContext())

    def pooled():
        with forgetting():  # every crop recognised (no read remembered from an earlier round)
            return reader.read_batches(batches)

    def batch_by_batch():
        with forgetting():
            return [reader.read(b, h) for b, h in batches]

    def ocr_seconds(read):
        before = reader.stage_seconds["ocr"]
        read()
        return reader.stage_seconds["ocr"] - before

    assert batch_by_batch() == pooled()  # warm-up, and the same reads
    crops = sum(len(t.plates) for t in reader.last_trace)  # every batch's traces, after read_batches
    alone, together = [], []
    for _ in range(ROUNDS):  # interleaved, so that a change of machine load hits both
        alone.append(ocr_seconds(batch_by_batch))
        together.append(ocr_seconds(pooled))
    benchmark.pedantic(pooled, rounds=1, iterations=1)
    ratio = min(together) / min(alone)
    benchmark.extra_info.update({
        "batch_by_batch_ocr_s": min(alone), "pooled_ocr_s": min(together), "ratio": ratio,
        "read_calls": len(batches), "windows": len(images), "crops": crops,
        "threads": torch.get_num_threads(), "load_average": list(os.getloadavg())})
    if request.config.getoption("benchmark_only"):
        assert ratio <= TARGET_RATIO, benchmark.extra_info
