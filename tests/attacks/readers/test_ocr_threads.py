"""The recognizer's per-crop tail runs on one thread (attacks/readers/plates/ocr.py ``one_thread``): the same raw
strings and confidences as with the caller's threads, and the caller's thread count is back after it."""

from __future__ import annotations

import contextlib

import numpy as np
import pytest
import torch

import attacks
from attacks.readers.plates import ocr as plate_ocr
from attacks.readers.plates.easyocr_models import load_easyocr
from benchmark.scenes import load_scenes


def _crops(n_scenes: int = 2) -> list[np.ndarray]:
    scenes = load_scenes("synthetic", "val", n_scenes, (512, 1024), 0)
    images = torch.from_numpy(np.stack([s.image for s in scenes])).permute(0, 3, 1, 2).float()
    reader = attacks.load("lpdr-oracle")
    reader.read(images, attacks.ReadHints(vehicle_boxes=[[v.box_xyxy for v in s.vehicles] for s in scenes]))
    rgb = (images.clamp(0, 1) * 255).round().byte().permute(0, 2, 3, 1).numpy()
    return [image[y0:y1, x0:x1] for image, trace in zip(rgb, reader.last_trace) for _, (x0, y0, x1, y1) in trace.plates]


@pytest.mark.slow
def test_reads_on_one_thread_equal_reads_on_the_callers_threads(monkeypatch):
    ocr = load_easyocr(False)
    crops = _crops()
    rows = {i: plate_ocr.prepare_crop(c) for i, c in enumerate(crops)}
    threads = torch.get_num_threads()
    torch.set_num_threads(2)
    try:
        one = plate_ocr.recognize_rows(ocr, rows)
        with monkeypatch.context() as mp:
            mp.setattr(plate_ocr, "one_thread", contextlib.nullcontext)
            callers = plate_ocr.recognize_rows(ocr, rows)
        assert torch.get_num_threads() == 2
    finally:
        torch.set_num_threads(threads)
    assert len(crops) >= 5 and any(score > 0.5 for _, score in one.values())  # real plates were read
    assert one == callers


def test_one_thread_gives_the_threads_back_even_on_an_error():
    threads = torch.get_num_threads()
    with pytest.raises(KeyError):
        with plate_ocr.one_thread():
            assert torch.get_num_threads() == 1
            raise KeyError("inside")
    assert torch.get_num_threads() == threads
