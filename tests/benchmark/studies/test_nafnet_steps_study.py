"""The known-pairs NAFNet step study (benchmark/studies/nafnet_steps_study.py): its flattening rule against a
closed form, and its fit being the attacker's own fit."""

from __future__ import annotations

import dataclasses
import json

import numpy as np
import pytest
import torch
from scipy.optimize import brentq

import lenses
from attacks.restorers.nafnet_known_pairs import NafnetKnownPairs
from benchmark.results.metrics import psnr
from benchmark.store.profiles import get_profile
from benchmark.runner.config import RunConfig
from benchmark.scenes import load_scenes
from benchmark.runner.sensing import sense, to_tensor
from benchmark.studies import nafnet_steps_study as nafnet_steps
from benchmark.runner.tasks import fit_context


def _records(steps, values):
    return [{"step": int(s), "psnr_db": float(v)} for s, v in zip(steps, values)]


def test_flattening_step_of_a_saturating_curve_matches_the_closed_form():
    # PSNR(s) = 30 - 5 exp(-s / 100): the last 20 % of s steps add g(s) = 5 (exp(-0.8 s/100) - exp(-s/100)),
    # which rises, peaks, then falls; the curve is flat from the root of g = 0.2 on the falling side.
    steps = np.arange(10, 2001, 10)
    chosen = nafnet_steps.flattening_step(_records(steps, 30 - 5 * np.exp(-steps / 100)))
    def gain(s):
        return 5 * (np.exp(-0.008 * s) - np.exp(-0.01 * s)) - 0.2
    root = brentq(gain, 200, 2000)
    assert root <= chosen < root + 10


def test_a_curve_still_rising_gives_the_last_checkpoint_and_a_late_rise_is_not_missed():
    steps = np.arange(10, 101, 10)
    # Rising 0.02 dB a step: a short fit's last 20 % adds little, but the longer fits' add 0.4 dB, so no
    # budget counts as flat.
    assert nafnet_steps.flattening_step(_records(steps, 0.02 * steps)) == 100
    plateau_then_rise = np.where(steps < 70, 20.0, 20.0 + 0.1 * (steps - 60))
    assert nafnet_steps.flattening_step(_records(steps, plateau_then_rise)) == 100


@pytest.mark.slow
def test_the_study_fit_is_the_attacker_s_fit(tmp_path):
    profile = dataclasses.replace(get_profile("smoke"), restorer_steps=12)
    body = nafnet_steps.run(tmp_path / "study.json", tmp_path / "chart.png", profile, "defocus", 0, (4, 8, 12))
    assert [r["step"] for r in body["records"]] == [4, 8, 12] and body["complete"]
    assert np.all(np.diff([r["fit_s"] for r in body["records"]]) > 0)
    assert json.loads((tmp_path / "study.json").read_text())["chosen_steps"] in (4, 8, 12)
    assert (tmp_path / "chart.png").read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
    # The attacker, fitted for 12 steps on the same lens and seed, restores the val scenes to the last
    # checkpoint's PSNR: same data, recipe and initial weights.
    cfg = RunConfig(lenses=["defocus"], attacks=[], scenes="synthetic", profile=profile, seeds=[0], cache_dir=tmp_path)
    lens = lenses.load("defocus", profile=profile, seed=0, cache_dir=tmp_path, scenes="synthetic")
    attacker = NafnetKnownPairs(backend="torch")
    attacker.fit(fit_context(lens, cfg, 0, None))
    sharp = to_tensor(load_scenes("synthetic", "val", profile.n_val, profile.image_size, 0))
    with torch.no_grad():
        restored = attacker.restore(sense(lens, sharp, profile.batch_size, 0, "cpu"))
    assert float(psnr(restored, sharp).mean()) == pytest.approx(body["records"][-1]["psnr_db"], abs=1e-3)
