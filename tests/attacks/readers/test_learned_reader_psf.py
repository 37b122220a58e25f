"""learned-reader-psf: the reader of Wiener estimates reads plates through a blurring lens that the sharp-plate
network cannot read on the sensor image, with no per-lens fit; its shipped family pre-training reads a lens it
never drew better than its sharp start, scores its recorded held-out curve, and leaves clean plates to the
sharp start; its per-lens fine-tune starts from the family network, keeps it when it cannot beat it, and is
deterministic and cached."""

from __future__ import annotations

import numpy as np
import pytest
import torch

import lenses
from attacks.base import AttackBudget, FitContext, ReadHints
from attacks.readers.learned_reader import LearnedReader
from attacks.readers.learned_reader_psf import LearnedReaderPSF, LearnedReaderPSFTuned
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
    assert psf_reader.describe()["shipped_weights"]["file"] == "learned-reader-psf-family-s0.safetensors"


def test_without_a_lens_it_reads_the_images_as_they_are():
    reader = LearnedReaderPSF()
    reader.fit(FitContext(budget=AttackBudget(profile="quick")))
    images = torch.rand(2, 3, 40, 90)
    assert torch.equal(reader.reader_input(images), images)


def test_the_family_pretraining_reads_an_undrawn_lens_better_than_its_sharp_start():
    """random-zernike lies outside the family's draws (a test lens): its 64 px plates."""
    lens = lenses.load("random-zernike")
    family, sharp = LearnedReaderPSF(), LearnedReaderPSF(family=False)
    for reader in (family, sharp):
        reader.fit(FitContext(lens=lens, budget=AttackBudget(profile="quick")))
    assert sharp.describe()["shipped_weights"]["file"] == "learned-reader-sharp-s0.safetensors"
    batch = plates_through(lens, 64, n=48)
    ours, start = accuracy(family, batch), accuracy(sharp, batch)
    assert ours >= start + 0.1, (ours, start)


def test_the_shipped_family_pretraining_scores_its_recorded_curve():
    """Its held-out set (Wiener estimates through lenses of another seed stream) is a function of the seed:
    the weights, loaded through the checked path, score now what their provenance recorded."""
    from attacks.readers.learned_reader import unpack_weights
    from attacks.readers.learned_reader_psf import family_key
    from attacks.training.lens_family import LensFamily
    from attacks.training.plate_reader_training import plate_accuracy
    from attacks.training.reader_family_training import FAMILY_BUDGET, family_held_out
    from attacks.training.shipped_weights import find_shipped
    from common.plate_render import PLATE_FORMAT

    shipped = find_shipped(LearnedReaderPSF.name, family_key(PLATE_FORMAT, reads="wiener"))
    assert shipped is not None, "the package ships learned-reader-psf's family pre-training"
    net = LearnedReader.build(PLATE_FORMAT, 0)
    curve = unpack_weights(net, shipped.data)
    assert curve is not None and shipped.provenance["made"]["reads"] == "wiener"
    recorded = curve.per_width[curve.kept]
    held = family_held_out(LensFamily(), FAMILY_BUDGET, PLATE_FORMAT, 0, "wiener")
    for width in recorded:
        score = float(np.mean([plate_accuracy(net.eval(), sets[width]) for _, sets in held]))
        assert score == pytest.approx(recorded[width], abs=1.5 / FAMILY_BUDGET.steps.eval_plates), width


def test_without_a_lens_the_sharp_start_reads_clean_plates():
    reader = LearnedReaderPSF()
    reader.fit(FitContext(budget=AttackBudget(profile="quick")))
    assert reader.describe()["shipped_weights"]["file"] == "learned-reader-sharp-s0.safetensors"
    plates = simulate_plates(None, 200, (32, 32), np.random.default_rng(2026), torch.Generator().manual_seed(2026), 0.0,
                             "LLDDDLL", jitter=False)
    assert accuracy(reader, plates) >= 0.95


def test_the_per_lens_fine_tune_starts_from_the_family_network_and_never_keeps_worse_than_it():
    """Smoke budget on defocus: the start is scored first (step 0) and the weights of the best evaluation are
    kept, so the fit's held-out score is at least the family network's; two fits are identical; a second fit
    on the same store loads the first; the reader's own crops hold no blur margin (it reads Wiener estimates)."""
    from test_learned_reader import MemoryStore

    lens = lenses.load("defocus")
    store = MemoryStore()
    first, again, alone = LearnedReaderPSFTuned(), LearnedReaderPSFTuned(), LearnedReaderPSFTuned()
    report = first.fit(FitContext(lens=lens, budget=AttackBudget(profile="smoke"), artifacts=store))
    curve = first.curve
    assert first.trained and curve is not None and curve.steps[0] == 0 and report.curve is not None
    assert curve.accuracy[curve.kept] == max(curve.accuracy) >= curve.accuracy[0]
    assert first.fit_key is not None and first.fit_key["start"]["shipped"] == "learned-reader-psf-family-s0.safetensors"
    assert first.spread_px == 0.0 and "fine-tuned on this lens" in first.describe()["recipe"]
    again.fit(FitContext(lens=lens, budget=AttackBudget(profile="smoke"), artifacts=store))
    assert again.trained is False and again.curve == curve
    alone.fit(FitContext(lens=lens, budget=AttackBudget(profile="smoke")))
    assert (alone.curve.steps, alone.curve.accuracy) == (curve.steps, curve.accuracy) and all(torch.equal(a, b) for a, b in zip(alone.net.state_dict().values(),
                                                                         first.net.state_dict().values()))
