"""Plate charts (benchmark/results/charts/plate_width.py, plate_gallery.py): accuracy-by-width curves and the crop gallery."""

from __future__ import annotations

import numpy as np
import pytest
import torch

from attacks import PlateRead
from benchmark.results.charts import plate_gallery, plate_width
from benchmark.results.plate_scoring import readable
from benchmark.scenes import load_scenes

PNG_MAGIC = b"\x89PNG\r\n\x1a\n"


def records() -> list[dict]:
    rows = []
    for lens, attack, p_correct in [("sharp", "lpdr-oracle", 1.0), ("gp", "lpdr-oracle", 0.0),
                                    ("gp", "nafnet-known-pairs>lpdr-oracle", 0.5)]:
        for width, correct in [(20, False), (70, p_correct >= 0.5), (150, p_correct > 0), (150, p_correct == 1.0)]:
            rows.append({"lens": lens, "attack": attack, "seed": 0, "scene": "s", "truth": "AB123CD",
                         "width_px": width, "read": "", "detected": True, "correct": str(correct), "cer": 0.0})
    return rows


def test_width_accuracy_bins_and_pools():
    curves = plate_width.width_accuracy(records(), bins_px=(16, 64, 128))
    edges, acc, counts = curves[("sharp", "lpdr-oracle")]
    assert list(edges) == [16, 64, 128] and list(counts) == [1, 1, 2]
    np.testing.assert_allclose(acc, [0.0, 1.0, 1.0])
    np.testing.assert_allclose(curves[("gp", "nafnet-known-pairs>lpdr-oracle")][1], [0.0, 1.0, 0.5])


def test_width_chart_has_one_panel_per_lens_and_one_curve_per_chain(tmp_path):
    path = plate_width.write_plate_width_chart(records(), tmp_path / "plates" / "width.png")
    assert path.read_bytes()[:8] == PNG_MAGIC
    sharp, gp = [ax for ax in plate_width.plate_width_figure(records()).axes if ax.get_visible()]
    assert (sharp.get_title(loc="left"), gp.get_title(loc="left")) == ("lens: sharp", "lens: gp")
    assert len(sharp.containers) == 1 and len(gp.containers) == 2  # one curve with error bars per chain
    assert {t.get_text().split(" (")[0] for t in gp.get_legend().get_texts()} == {
        "lpdr-oracle", "nafnet-known-pairs>lpdr-oracle"}
    with pytest.raises(ValueError, match="no plate records"):
        plate_width.write_plate_width_chart([], tmp_path / "empty.png")


def test_gallery_shows_every_source_and_what_was_read(tmp_path):
    scenes = load_scenes("synthetic", "val", 4, (512, 1024), 0)
    sharp = torch.from_numpy(np.stack([s.image for s in scenes])).permute(0, 3, 1, 2)
    index, plate = max(((i, p) for i, s in enumerate(scenes) for p in s.plates if readable(p)),
                       key=lambda ip: ip[1].box_xyxy[2] - ip[1].box_xyxy[0])  # the gallery's first row
    reads = {"sharp": [[PlateRead(plate.text, tuple(map(float, plate.box_xyxy)), 0.9)] if i == index else []
                       for i in range(len(scenes))]}
    images = {"sharp": sharp, "sensor": sharp * 0.5, "wiener-known-psf": sharp.flip(-1)}
    path = plate_gallery.write_plate_gallery(images, scenes, reads, tmp_path / "gallery.png", max_plates=3)
    assert path.read_bytes()[:8] == PNG_MAGIC
    axes = plate_gallery.plate_gallery_figure(images, scenes, reads, max_plates=3).axes
    assert len(axes) == 3 * 3
    assert [ax.get_title() for ax in axes] == list(images) + [""] * 6  # the columns' sources, on top
    reads_shown = [ax.xaxis.label.get_text() for ax in axes]  # under each crop: what was read
    assert reads_shown[0] == plate.text and all(t == "" for t in reads_shown[1::3] + reads_shown[2::3])
    with pytest.raises(ValueError, match="expected"):
        plate_gallery.write_plate_gallery({"sharp": sharp[:1]}, scenes, {}, tmp_path / "bad.png")
