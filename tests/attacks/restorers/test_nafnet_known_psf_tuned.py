"""nafnet-known-psf-tuned: a lens-access attacker whose fine-tune starts from nafnet-known-psf itself (the
lens's own PSF and gain, the shipped pre-training) and keeps that start when its steps make things worse."""

from __future__ import annotations

import pytest
import torch

import attacks
from attacks.base import AttackBudget, FitContext, ThreatModel
from attacks.restorers import nafnet_known_pairs
from attacks.restorers.nafnet_known_psf import known_psf_key
from attacks.training import psf_restorer_training
from benchmark.runner.sensing import sense, to_tensor
from benchmark.scenes.loading import load_scenes
from lenses.builtin import SPEC_DIR
from lenses.lens import Lens
from lenses.spec import load_spec


@pytest.fixture(scope="module")
def context() -> FitContext:
    lens = Lens(load_spec(SPEC_DIR / "defocus.toml"))
    sharp = to_tensor(load_scenes("synthetic", "train", 8, (128, 256), 3))
    sensor = sense(lens, sharp, 4, 3, "cpu")

    def pairs():
        yield sensor, sharp

    # The quick profile's restorer (the shipped pre-training), fine-tune steps of 4 crops of 64 px, the
    # first held-out evaluation (at 25 steps) within the budget.
    budget = AttackBudget(profile="quick", restorer_steps=4, batch_size=4, crop_px=64, max_train_images=8)
    return FitContext(lens=lens, train_pairs=pairs, seed=0, budget=budget)


def test_it_is_a_lens_access_attacker_that_needs_the_known_pairs_too():
    tuned = attacks.load("nafnet-known-psf-tuned")
    assert tuned.threat_model is ThreatModel.LENS_ACCESS
    assert tuned.requires == {"lens", "train_pairs"}


def test_a_fine_tune_that_only_hurts_hands_back_nafnet_known_psf_itself(context, monkeypatch):
    # Injected fault: a learning rate that wrecks the network by the first evaluation.
    monkeypatch.setattr(psf_restorer_training, "FINE_TUNE_LR", 0.5)
    tuned = attacks.load("nafnet-known-psf-tuned", backend="torch")
    report = tuned.fit(context)
    assert report.curve is not None and tuple(report.curve.steps) == (0, 25)
    start, after = report.curve.scores
    # (it diverges: NaN weights score NaN, which must not be kept either)
    assert not after > start - 1.0, "the injected learning rate did not hurt: the test proves nothing"
    assert report.curve.kept_step == 0
    zero_shot = attacks.load("nafnet-known-psf", backend="torch")
    zero_shot.fit(context)
    # So the runner may restore once for both: they claim one restoration_key.
    assert tuned.restoration_key() is not None and tuned.restoration_key() == zero_shot.restoration_key()
    with torch.no_grad():
        sensor = next(context.train_pairs())[0][:2]
        torch.testing.assert_close(tuned.restore(sensor), zero_shot.restore(sensor), atol=1e-6, rtol=0)


def test_its_start_is_the_lens_psf_where_the_known_pairs_attacker_measures_its_own(context):
    # Step 0 of each fine-tune is its start on the same held-out pair: the lens's PSF and the one measured
    # from 8 small pairs give different starts, so the two attackers are not one.
    tuned = attacks.load("nafnet-known-psf-tuned", backend="torch").fit(context)
    pairs = attacks.load("nafnet-known-pairs-tuned", backend="torch").fit(context)
    assert tuned.curve is not None and pairs.curve is not None
    assert tuned.curve.scores[0] != pytest.approx(pairs.curve.scores[0], abs=1e-3)


@pytest.mark.slow
def test_a_fine_tune_that_moved_claims_another_restoration_key(context, monkeypatch):
    # With no gain required, the first evaluation's weights are kept: not the zero-shot's any more.
    real = psf_restorer_training.fine_tune
    monkeypatch.setattr(nafnet_known_pairs, "fine_tune", lambda *a, **k: real(*a, **{**k, "min_gain_db": -1e9}))
    tuned = attacks.load("nafnet-known-psf-tuned", backend="torch")
    report = tuned.fit(context)
    assert report.curve is not None and report.curve.kept_step > 0
    zero_shot = attacks.load("nafnet-known-psf", backend="torch")
    zero_shot.fit(context)
    assert tuned.restoration_key() != zero_shot.restoration_key()
    # The backend is part of the claim: ONNX Runtime's float rounding is not torch's.
    assert zero_shot.restoration_key() != known_psf_key(zero_shot.network, zero_shot._otf, zero_shot._gain, "onnx")
