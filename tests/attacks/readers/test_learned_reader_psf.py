"""learned-reader-psf: the sharp-plate reader reading the Wiener estimate of the known lens reads plates
through a blurring lens that the same network cannot read on the sensor image, with no per-lens fit."""

from __future__ import annotations

import numpy as np
import torch

import lenses
from attacks.base import AttackBudget, FitContext, ReadHints
from attacks.readers.learned_reader import LearnedReader
from attacks.readers.learned_reader_psf import LearnedReaderPSF
from attacks.readers.plates.plate_sim import psf_radius_px, simulate_plates


def plates_through(lens, width: int, n: int = 24):
    psf = lens.psf().detach()
    with torch.no_grad():
        return simulate_plates(lambda x, g: lens(x, generator=g), n, (width, width), np.random.default_rng([5, width]),
                               torch.Generator().manual_seed(width), psf_radius_px(psf), "LLDDDLL", psf.shape[-1] // 2,
                               jitter=False)


def accuracy(reader, batch) -> float:
    reads = reader.read(batch.images, ReadHints(plate_boxes=[[box] for box in batch.boxes]))
    return float(np.mean([r[0].text == t for r, t in zip(reads, batch.texts)]))


def test_it_reads_through_the_defocus_lens_where_the_same_network_on_the_sensor_image_cannot():
    lens = lenses.load("defocus")
    psf_reader, sharp_start = LearnedReaderPSF(), LearnedReader()
    report = psf_reader.fit(FitContext(lens=lens, budget=AttackBudget(profile="quick")))
    sharp_start.fit(FitContext(budget=AttackBudget(profile="quick")))  # no lens: the sharp start as it is
    sharp_start.spread_px = psf_radius_px(lens.psf().detach())          # its crops as a fit on the lens cuts them
    batch = plates_through(lens, 128)
    ours, theirs = accuracy(psf_reader, batch), accuracy(sharp_start, batch)
    assert ours >= 0.75 and theirs <= 0.25, (ours, theirs)
    assert report.curve is None and set(report.stage_seconds) == {"start"}  # nothing trained per lens
    assert psf_reader.describe()["shipped_weights"]["file"] == "learned-reader-sharp-s0.safetensors"


def test_without_a_lens_it_reads_the_images_as_they_are():
    reader = LearnedReaderPSF()
    reader.fit(FitContext(budget=AttackBudget(profile="quick")))
    images = torch.rand(2, 3, 40, 90)
    assert torch.equal(reader.reader_input(images), images)
