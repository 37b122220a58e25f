"""Reading with the plate stages' memory (attacks/readers/plates/memo.py) scores every chain exactly as reading
without it: same rows' plate metrics and intervals, same per-plate records, same reads; it only
recognises fewer crops (the `raw` chain re-reads the sensor chain's crops) and segments fewer images."""

from __future__ import annotations

import numpy as np
import pytest
import torch

import attacks
import attacks.readers.lpdr
from attacks.restorers.gray_world import gray_world_balance
from attacks.readers.plates.memo import forgetting
from benchmark.runner.evaluation import Attacked, Target, run_reader
from benchmark.store.profiles import get_profile
from benchmark.runner.rows import RowBuilder
from benchmark.runner.config import RunConfig
from benchmark.scenes import load_scenes
from benchmark.runner.sensing import to_tensor

TIMING = ("images_per_s", "fit_s")  # measured seconds: not the same twice


class SceneLabels:
    """A segmenter returning the scenes' own train ids (a perfect network), counting the images it saw."""

    def __init__(self, scenes) -> None:
        self.labels = {tuple(s.image[::7, ::7, 0].ravel()): torch.from_numpy(s.labels.astype(np.int64)) for s in scenes}
        self.size = scenes[0].labels.shape
        self.images_seen = 0

    def __call__(self, images: torch.Tensor) -> torch.Tensor:
        self.images_seen += images.shape[0]
        return torch.stack([self._labels(im) for im in images])

    def _labels(self, image: torch.Tensor) -> torch.Tensor:
        # Restorers change pixels: find the scene by its nearest thumbnail (at the scenes' size; lpdr
        # may ask at another, its vehicle_scale), and answer at the size asked for.
        full = torch.nn.functional.interpolate(image[None], size=self.size, mode="nearest")[0]
        thumb = full.permute(1, 2, 0).numpy()[::7, ::7, 0].ravel()
        key = min(self.labels, key=lambda k: float(np.abs(np.asarray(k) - thumb).sum()))
        labels = self.labels[key][None, None].float()
        return torch.nn.functional.interpolate(labels, size=image.shape[1:], mode="nearest")[0, 0].long()


def _attack(cfg: RunConfig, scenes, sensor: torch.Tensor, same_segmenter: bool):
    seg_sensor = SceneLabels(scenes)
    seg_restored = seg_sensor if same_segmenter else SceneLabels(scenes)
    target = Target("fake", scenes, sensor, sensor, attacks.FitContext(segmenter=seg_sensor),
                    seg_sensor, seg_restored)
    out = Attacked(restored={"raw": sensor.clone(), "gray-world": gray_world_balance(sensor)},
                   described={"raw": {"name": "raw"}, "gray-world": {"name": "gray-world"}}, references={"raw"},
                   threat_models={"raw": attacks.ThreatModel.SENSOR_ACCESS, "gray-world": attacks.ThreatModel.SENSOR_ACCESS})
    builder = RowBuilder(cfg, "fake", 0, {"lens": "fake"}, {"device": "cpu"})
    hits = {}
    for name in ("lpdr", "lpdr-oracle"):
        reader = attacks.load(name)
        run_reader(target, reader, cfg, builder, out)
        hits[name] = (reader.vehicle_cache_hits, reader.ocr_cache_hits)
    rows = [(r.attack, r.kind, r.status, {k: v for k, v in r.metrics.items()
                                          if k not in TIMING and not k.endswith("_s_per_image")}, r.intervals)
            for r in out.rows]
    reads = {k: [[(p.text, p.box_xyxy, p.score) for p in per] for per in v] for k, v in out.reads.items()}
    return rows, out.plates, reads, seg_sensor.images_seen + (0 if same_segmenter else seg_restored.images_seen), hits


@pytest.mark.slow
def test_remembered_reads_score_every_chain_as_computing_them_again(monkeypatch):
    cfg = RunConfig(["fake"], None, "synthetic", get_profile("smoke"), [0])
    scenes = load_scenes("synthetic", "val", 2, (512, 1024), 0)
    sensor = to_tensor(scenes)
    recognised = []
    read_plates = attacks.readers.lpdr.read_plates
    monkeypatch.setattr(attacks.readers.lpdr, "read_plates", lambda ocr, crops, fmt: recognised.append(len(crops))
                        or read_plates(ocr, crops, fmt))
    for same_segmenter in (False, True):  # a lens's own net and the clean net; the sharp task's one net
        recognised.clear()
        with forgetting():
            old = _attack(cfg, scenes, sensor, same_segmenter)
        old_crops = sum(recognised)
        recognised.clear()
        new = _attack(cfg, scenes, sensor, same_segmenter)
        assert new[:3] == old[:3]
        assert sum(n for _, _, _, m, _ in new[0] for k, n in m.items() if k == "n_plates") >= 6  # real plates
        assert all(m["plate_cer"] < 1 for _, _, _, m, _ in new[0])  # and real reads in every chain
        # What was saved: the raw chain's crops are never recognised twice.
        assert sum(recognised) < old_crops and new[4]["lpdr-oracle"][1] > 0
        # Segmentation: 3 chains x 2 images without memory; with one network the raw chain re-uses the sensor's.
        assert old[3] == 6 and new[3] == (4 if same_segmenter else 6)
        assert new[4]["lpdr"][0] == (2 if same_segmenter else 0)
