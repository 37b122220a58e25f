"""Batched plate reading (attacks/readers/plates/ocr.py, attacks/readers/lpdr.py) reads exactly what the reader read before
it batched (one image per pass, EasyOCR's own ``recognize`` one crop at a time: tests/plate_reference.py),
and the lpdr reader segments each image once per segmenter."""

from __future__ import annotations

import numpy as np
import pytest
import torch

import attacks
import attacks.readers.lpdr
from attacks.readers.plates import ocr as plate_ocr
from attacks.readers.plates.easyocr_models import load_easyocr
from attacks.readers.plates.memo import forgetting
from benchmark.scenes import load_scenes
from plate_reference import plate_crops, recognize_one_at_a_time  # tests/plate_reference.py


def _scenes(size: tuple[int, int], n: int):
    scenes = load_scenes("synthetic", "val", n, size, 0)
    images = torch.from_numpy(np.stack([s.image for s in scenes])).permute(0, 3, 1, 2).float()
    return images, attacks.ReadHints(vehicle_boxes=[[v.box_xyxy for v in s.vehicles] for s in scenes])


CONVOLUTION_ROUNDING = 1e-3
"""How far a read's confidence may move when its convolutions run in a batch instead of alone. Bit for
bit on the machines this was written on; on a CPU with AVX2 and no AVX-512 (2026-11-27) torch's
convolutions on a batch differed from one crop's by 3e-6 and a score by 4e-8."""


def _as_tuples(reads):
    return [[(r.text, r.box_xyxy, r.score) for r in per_image] for per_image in reads]


@pytest.mark.parametrize("size,n", [((128, 256), 4), ((512, 1024), 3)], ids=["smoke", "quick"])
def test_batched_reads_equal_reading_each_crop_alone(monkeypatch, size, n):
    """Same strings, boxes and scores (bit for bit) as one image per pass and one recognizer pass per crop
    (both with the convolutions in torch, as EasyOCR runs them; ONNX Runtime's: tests/attacks/readers/test_ocr_onnx.py)."""
    monkeypatch.setattr(plate_ocr, "FEATURE_BACKEND", "torch")
    images, hints = _scenes(size, n)
    reader = attacks.load("lpdr-oracle")
    reader.fit(attacks.FitContext())
    with forgetting():  # both ways recognise every crop (no read remembered from the other)
        batched = reader.read(images, hints)
        crops = sum(len(t.plates) for t in reader.last_trace)
        with monkeypatch.context() as mp:
            mp.setattr(attacks.readers.lpdr, "read_plates", recognize_one_at_a_time)
            alone = [reader.read(images[i:i + 1], attacks.ReadHints(vehicle_boxes=hints.vehicle_boxes[i:i + 1]))[0]
                     for i in range(n)]
    assert _as_tuples(batched) == _as_tuples(alone)
    if size == (512, 1024):
        assert crops >= 5 and sum(map(len, batched)) >= 2  # the comparison covered real reads


def test_crops_of_several_widths_are_grouped_and_read_like_alone(monkeypatch):
    """Grouping by padded width reads every crop as EasyOCR reads it alone. Both sides run the
    convolutions in torch: ONNX Runtime's agree with torch's to float rounding but not bit for bit on
    every CPU (tests/attacks/readers/test_ocr_onnx.py), and this test is about the grouping."""
    monkeypatch.setattr(plate_ocr, "FEATURE_BACKEND", "torch")
    ocr = load_easyocr(False)
    rng = np.random.default_rng(0)
    images, hints = _scenes((512, 1024), 2)
    reader = attacks.load("lpdr-oracle")
    reader.read(images, hints)
    crops = list(plate_crops(reader, images))
    crops.append(rng.integers(0, 255, (20, 90, 3), dtype=np.uint8))  # noise: read with low confidence
    crops.append(np.zeros((0, 4, 3), np.uint8))                       # empty: reads ""
    widths = {plate_ocr.padded_width(plate_ocr.prepare_crop(c)) for c in crops if c.size}
    assert len(widths) >= 2
    batched, alone = plate_ocr.read_plates(ocr, crops, "LLDDDLL"), recognize_one_at_a_time(ocr, crops, "LLDDDLL")
    assert [r.raw for r in batched] == [r.raw for r in alone]
    np.testing.assert_allclose([r.score for r in batched], [r.score for r in alone], rtol=0, atol=CONVOLUTION_ROUNDING)


def test_shared_features_equal_the_recognizer_crop_by_crop():
    model = load_easyocr(False).recognizer
    batch = torch.rand(3, 1, 64, 192) * 2 - 1
    shared = plate_ocr.SharedFeatures(model)
    with torch.no_grad():
        alone = torch.cat([model(batch[i:i + 1], None) for i in range(3)])
        features_alone = torch.cat([shared.features(batch[i:i + 1]) for i in range(3)])
        features_batched = shared.features(batch)
        shared.features = PerCrop(shared.features)  # the tail alone: the same features as crop by crop
        tail_per_crop = shared(batch)
        together = model(batch, None)
    # The convolutions on a batch equal them crop by crop to float rounding (3e-6 of the scale on an AVX2 CPU) ...
    scale = float(features_alone.abs().max())
    assert float((features_batched - features_alone).abs().max()) <= 1e-5 * scale
    # ... and the quantized tail run per crop is exactly EasyOCR's on one crop.
    assert torch.equal(tail_per_crop, alone)
    # Why the tail runs per crop: the quantized tail of a plain batch depends on its neighbours.
    assert not torch.equal(together, alone)


class PerCrop(torch.nn.Module):
    """A feature extractor run one crop at a time."""

    def __init__(self, features: torch.nn.Module) -> None:
        super().__init__()
        self.inner = features

    def forward(self, x: torch.Tensor) -> torch.Tensor:
        return torch.cat([self.inner(x[i:i + 1]) for i in range(x.shape[0])])


def test_padded_width_is_easyocr_s():
    assert plate_ocr.padded_width(np.zeros((64, 64), np.uint8)) == 64
    assert plate_ocr.padded_width(np.zeros((64, 65), np.uint8)) == 128
    assert plate_ocr.padded_width(np.zeros((40, 200), np.uint8)) == 320
    assert plate_ocr.padded_width(np.zeros((100, 30), np.uint8)) == 256  # tall: ratio inverted, 3.33 -> 4


class CountingSegmenter:
    """Train ids of every scene (one car per scene's vehicles) and how many images it segmented."""

    def __init__(self, scenes) -> None:
        self.labels = torch.from_numpy(np.stack([s.labels for s in scenes]).astype(np.int64))
        self.images_seen = 0

    def __call__(self, images: torch.Tensor) -> torch.Tensor:
        self.images_seen += images.shape[0]
        labels = self.labels[: images.shape[0], None].float()  # at the size asked for (lpdr's vehicle_scale)
        return torch.nn.functional.interpolate(labels, size=images.shape[2:], mode="nearest")[:, 0].long()


def test_lpdr_segments_each_image_once_per_segmenter():
    scenes = load_scenes("synthetic", "val", 2, (128, 256), 0)
    images = torch.from_numpy(np.stack([s.image for s in scenes])).permute(0, 3, 1, 2).float()
    segment = CountingSegmenter(scenes)
    first, second = attacks.load("lpdr"), attacks.load("lpdr")
    reads = first.read(images, attacks.ReadHints(segment=segment))
    assert segment.images_seen == 2 and first.vehicle_cache_hits == 0
    assert second.read(images, attacks.ReadHints(segment=segment)) == reads  # another chain, same images
    assert segment.images_seen == 2 and second.vehicle_cache_hits == 2
    assert [t.vehicles for t in second.last_trace] == [t.vehicles for t in first.last_trace]
    other = CountingSegmenter(scenes)  # another network: its own vehicles
    second.read(images, attacks.ReadHints(segment=other))
    assert other.images_seen == 2
    changed = images.clone()
    changed[1, :, 0, 0] += 0.5  # one pixel: another image; the batch is segmented whole again
    second.read(changed, attacks.ReadHints(segment=segment))
    assert segment.images_seen == 4


def test_read_batches_pools_crops_and_reads_like_read_batch_by_batch():
    """lpdr's read_batches recognises the crops of every batch together (fewer, fuller recognizer
    passes) and returns exactly what read returns batch by batch, traces included, for batches of
    different image sizes."""
    big, big_hints = _scenes((512, 1024), 3)
    small, small_hints = _scenes((256, 512), 2)
    batches = [(big[:2], attacks.ReadHints(vehicle_boxes=big_hints.vehicle_boxes[:2])),
               (small, small_hints),
               (big[2:], attacks.ReadHints(vehicle_boxes=big_hints.vehicle_boxes[2:]))]
    reader = attacks.load("lpdr-oracle")
    reader.fit(attacks.FitContext())
    calls: list[int] = []
    real = attacks.readers.lpdr.PlateReaderBase._recognise

    def counting(self, crops):
        calls.append(len(crops))
        return real(self, crops)

    with forgetting():
        one_by_one, traces = [], []
        for images, hints in batches:
            one_by_one.append(reader.read(images, hints))
            traces += [(t.plates, t.raw_texts) for t in reader.last_trace]
    with forgetting(), pytest.MonkeyPatch.context() as mp:
        mp.setattr(attacks.readers.lpdr.PlateReaderBase, "_recognise", counting)
        pooled = reader.read_batches(iter(batches))  # any iterable, consumed once
    assert [_as_tuples(b) for b in pooled] == [_as_tuples(b) for b in one_by_one]
    assert [(t.plates, t.raw_texts) for t in reader.last_trace] == traces
    assert len(calls) == 1 and calls[0] == sum(len(p) for p, _ in traces) >= 5
    assert sum(len(r) for b in pooled for r in b) >= 2  # the comparison covered real reads


def test_the_default_read_batches_is_read_per_batch():
    class Fixed(attacks.Reader):
        name = "fixed-reads"
        threat_model = attacks.ThreatModel.SENSOR_ACCESS

        def read(self, images, hints=None):
            return [[attacks.PlateRead(f"N{images.shape[-1]}", (0.0, 0.0, 1.0, 1.0), 1.0)] for _ in images]

    reads = Fixed().read_batches([(torch.zeros(2, 3, 4, 5), None), (torch.zeros(1, 3, 4, 7), None)])
    assert _as_tuples(reads[0]) == [[("N5", (0.0, 0.0, 1.0, 1.0), 1.0)]] * 2
    assert _as_tuples(reads[1]) == [[("N7", (0.0, 0.0, 1.0, 1.0), 1.0)]]


def test_a_subclass_that_overrides_read_is_read_through_it():
    class Shouting(attacks.readers.lpdr.LpdrOracle):
        name = "lpdr-oracle-shouting"

        def read(self, images, hints=None):
            return [[attacks.PlateRead(r.text + "!", r.box_xyxy, r.score) for r in per_image]
                    for per_image in super().read(images, hints)]

    images, hints = _scenes((512, 1024), 2)
    reader = Shouting()
    reader.fit(attacks.FitContext())
    (reads,) = reader.read_batches([(images, hints)])
    assert sum(map(len, reads)) >= 1 and all(r.text.endswith("!") for per_image in reads for r in per_image)


def test_second_pass_reuses_the_first_pass_output_of_a_crop_it_leaves_unchanged(monkeypatch):
    """EasyOCR re-reads crops read with confidence < 0.1 with their contrast stretched; a crop already at the
    target contrast reaches the network unchanged and is not recomputed, and every read is still what EasyOCR's
    own ``recognize`` reads crop by crop."""
    import easyocr.recognition

    monkeypatch.setattr(plate_ocr, "FEATURE_BACKEND", "torch")
    ocr = load_easyocr(False)
    rng = np.random.default_rng(0)
    blocks = np.kron(rng.integers(0, 2, (6, 24)), np.ones((4, 4))) * 255
    hard = np.repeat(blocks[..., None], 3, axis=2).astype(np.uint8)  # black and white, no text: full contrast
    noise = rng.integers(0, 256, (24, 96, 3), dtype=np.uint8)
    dim = (96 + noise // 4).astype(np.uint8)                         # grey noise: stretched in the second pass
    crops = [hard, dim]
    rows = {i: plate_ocr.prepare_crop(c) for i, c in enumerate(crops)}
    # The premise: both are re-read, and only the dim one is changed by the contrast stretch.
    assert [easyocr.recognition.contrast_grey(r)[0] >= 0.5 for r in rows.values()] == [True, False]
    instances = []

    class Counting(plate_ocr.SharedFeatures):
        def __init__(self, *args, **kwargs):
            super().__init__(*args, **kwargs)
            instances.append(self)

    monkeypatch.setattr(plate_ocr, "SharedFeatures", Counting)
    read = plate_ocr.recognize_rows(ocr, rows)
    alone = recognize_one_at_a_time(ocr, crops)
    assert [read[i][0] for i in rows] == [r.raw for r in alone]
    np.testing.assert_allclose([read[i][1] for i in rows], [r.score for r in alone], rtol=0,
                               atol=CONVOLUTION_ROUNDING)
    assert all(score < 0.1 for _, score in read.values())  # both went through the second pass
    (features,) = instances
    assert (len(features.seen), features.rows_remembered) == (3, 1)  # 2 first pass + the dim one stretched
