"""The ideal-observer reader: exact reads of clean plates, and its contract with the runner."""

from __future__ import annotations

import numpy as np
import pytest
import torch

import attacks
import lenses
from attacks.base import ReadHints
from attacks.readers.ideal_observer_reader import IdealObserverReader
from common.plate_render import random_plate_text, render_plate
from lenses.sensor import demosaic_bilinear, mosaic


def clean_sensor(lens: lenses.Lens, scene: torch.Tensor) -> torch.Tensor:
    """The sensor image with the noise left out: mean electrons, clip, 10-bit ADC, demosaic."""
    sensor = lens.sensor
    with torch.no_grad():
        mean = mosaic(lens.irradiance(scene) * sensor.electrons_per_unit()[:, None, None])
        digital = torch.round(mean.clamp(0, sensor.spec.full_well_e) * sensor.levels / sensor.spec.full_well_e)
    return demosaic_bilinear(digital / sensor.levels)


def street(plates: list[tuple[str, tuple[int, int, int, int], tuple[int, int, int], bool]]) -> torch.Tensor:
    """A (1, 3, 96, 256) scene: a textured grey street with the given plates pasted at their boxes."""
    rng = np.random.default_rng(0)
    image = 0.3 + 0.1 * rng.random((96, 256, 3))
    for text, (x0, y0, x1, y1), background, band in plates:
        image[y0:y1, x0:x1] = np.asarray(render_plate(text, (x1 - x0, y1 - y0), background, band)) / 255
    return torch.from_numpy(image).permute(2, 0, 1)[None].float()


@pytest.mark.slow
@pytest.mark.parametrize("lens_name, n_plates", [("ideal", 3), ("defocus", 1)])
def test_reads_clean_synthetic_plates_exactly(lens_name, n_plates):
    # The sharp lens makes the search hardest (a misplaced glyph scores very badly), so it reads all
    # three plates; one plate through defocus checks the fitted surround under a 15 px blur.
    rng = np.random.default_rng(1)
    plates = [(random_plate_text(rng), (10, 20, 58, 30), (236, 236, 228), False),
              (random_plate_text(rng), (91, 41, 155, 55), (240, 210, 40), True),
              (random_plate_text(rng), (170, 60, 250, 77), (236, 236, 228), True)][:n_plates]
    lens = lenses.load(lens_name)
    reader = attacks.load("ideal-observer")
    reader.fit(attacks.FitContext(lens=lens))
    sensor = clean_sensor(lens, street(plates))
    reads = reader.read(sensor, ReadHints(plate_boxes=[[box for _, box, _, _ in plates]]))[0]
    assert [r.text for r in reads] == [text for text, _, _, _ in plates]
    assert all(0 < r.score <= 1 for r in reads)


def test_needs_the_plate_boxes_and_a_lens_with_its_sensor():
    reader = IdealObserverReader()
    assert "no lens" in reader.skip_reason(attacks.FitContext())
    reader.fit(attacks.FitContext(lens=lenses.load("ideal")))
    with pytest.raises(ValueError, match="plate_boxes"):
        reader.read(torch.zeros(1, 3, 16, 16), attacks.ReadHints(vehicle_boxes=[[]]))


def test_registered_but_run_only_when_named():
    """Seconds per plate: `python -m benchmark list` shows it, a default run leaves it out."""
    assert attacks.available()["ideal-observer"] == "attacks.readers.ideal_observer_reader:IdealObserverReader"
    assert IdealObserverReader.run_by_default is False


@pytest.mark.slow
def test_reads_in_forked_workers_equal_the_reads_in_this_process_and_leave_no_process():
    from benchmark.runner.isolation import child_pids

    rng = np.random.default_rng(2)
    plates = [(random_plate_text(rng), (10, 20, 58, 30), (236, 236, 228), False),
              (random_plate_text(rng), (91, 41, 155, 55), (240, 210, 40), True),
              (random_plate_text(rng), (170, 60, 250, 77), (236, 236, 228), True)]
    lens = lenses.load("defocus")
    sensor = clean_sensor(lens, street(plates))
    images = torch.cat([sensor, sensor])
    hints = ReadHints(plate_boxes=[[plates[0][1], plates[1][1]], [plates[2][1], (0, 0, 4, 4)]])  # a box too small
    reads = {}
    for workers in (1, 2):
        reader = IdealObserverReader(workers=workers)
        reader.fit(attacks.FitContext(lens=lens))
        before = child_pids()
        reads[workers] = reader.read(images, hints)
        assert child_pids() <= before  # the pool's processes are reaped before read returns
    assert reads[1] == reads[2] and [len(r) for r in reads[1]] == [2, 1]
    # Two batches in one read_batches call share one pool (the widest box first): the same reads, per batch.
    batches = [(images[:1], ReadHints(plate_boxes=hints.plate_boxes[:1])),
               (images[1:], ReadHints(plate_boxes=hints.plate_boxes[1:]))]
    assert reader.read_batches(iter(batches)) == [reads[1][:1], reads[1][1:]]
    assert child_pids() <= before
    with pytest.raises(ValueError, match="workers"):
        IdealObserverReader(workers=0)
