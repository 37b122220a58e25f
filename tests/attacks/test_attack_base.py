"""The attacker base classes: requirement checks fail early and name what is missing."""

from __future__ import annotations

import dataclasses

import pytest
import torch

import attacks


class NeedsPairs(attacks.Restorer):
    name = "needs-pairs"
    threat_model = attacks.ThreatModel.KNOWN_PAIRS
    requires = frozenset({"train_pairs", "cache_dir"})

    def __init__(self) -> None:
        self.fitted = False

    def fit(self, ctx: attacks.FitContext) -> None:  # no super().fit(): the check still runs
        self.fitted = True

    def restore(self, sensor: torch.Tensor) -> torch.Tensor:
        return sensor


def test_fit_names_the_attacker_and_every_missing_field(tmp_path):
    attack = NeedsPairs()
    with pytest.raises(attacks.MissingRequirementError, match=r"needs-pairs.*\['cache_dir', 'train_pairs'\]"):
        attack.fit(attacks.FitContext())
    assert not attack.fitted
    attack.fit(attacks.FitContext(train_pairs=lambda: [], cache_dir=tmp_path))
    assert attack.fitted


def test_requires_must_name_context_fields():
    with pytest.raises(TypeError, match="lense"):

        class Typo(attacks.Restorer):  # noqa: F841 - defining it is the test
            name = "typo"
            threat_model = attacks.ThreatModel.LENS_ACCESS
            requires = frozenset({"lense"})


def test_plate_read_is_frozen_and_threat_models_are_strings():
    read = attacks.PlateRead("AB123", (1.0, 2.0, 30.0, 12.0), 0.9)
    with pytest.raises(dataclasses.FrozenInstanceError):
        read.text = "X"  # type: ignore[misc]
    assert attacks.ThreatModel("lens-access") is attacks.ThreatModel.LENS_ACCESS
    assert attacks.ThreatModel.SENSOR_ACCESS == "sensor-access"


def test_a_fit_that_returns_nothing_reports_an_empty_report_and_a_wrong_return_is_named():
    class Silent(attacks.Restorer):
        name = "silent"
        threat_model = attacks.ThreatModel.SENSOR_ACCESS

        def fit(self, ctx):
            pass

        def restore(self, sensor):
            return sensor

    class Chatty(Silent):
        name = "chatty"

        def fit(self, ctx):
            return {"fit_still_rising": True}

    assert Silent().fit(attacks.FitContext()) == attacks.FitReport()
    with pytest.raises(TypeError, match="Chatty.fit returned dict; it returns an attacks.FitReport"):
        Chatty().fit(attacks.FitContext())


@pytest.mark.parametrize("field, value, match", [
    ("profile", "fast", r"profile 'fast' is not a budget; valid: \['tiny', 'smoke', 'quick', 'paper'\]"),
    ("restorer_steps", 0, "restorer_steps must be an int >= 1"),
    ("crop_px", 33, "crop_px must be even"),
    ("nafnet_enc_blocks", (), "nafnet_enc_blocks must be a non-empty tuple"),
])
def test_a_bad_budget_names_its_field_and_what_is_valid(field, value, match):
    with pytest.raises(ValueError, match=match):
        attacks.AttackBudget(**{field: value})


def test_fit_curve_checks_its_shape_and_its_reason_to_stop():
    with pytest.raises(ValueError, match="2 steps but 1 scores"):
        attacks.FitCurve((1, 2), (0.5,), "held-out plate accuracy", "budget", 2)
    with pytest.raises(ValueError, match="'flattened' or 'budget'"):
        attacks.FitCurve((1,), (0.5,), "held-out plate accuracy", "tired", 1)


@pytest.mark.parametrize("shipped", ["nafnet-known-pairs-gp-quick-s0.json", "nafnet-generic-quick-s0.json"])
def test_the_quick_profile_budget_is_the_one_the_shipped_restorers_were_trained_under(shipped):
    # The shipped weights are found by their key; a budget that drifted from the profile would retrain them.
    import json
    from pathlib import Path

    from attacks.training.restorer_training import RestorerBudget
    from benchmark.store.profiles import get_profile

    key = json.loads((Path(attacks.__file__).parent / "weights" / shipped).read_text())["key"]
    budget = RestorerBudget.from_budget(get_profile("quick").attack_budget())
    assert json.loads(json.dumps(budget.to_dict())) == key["budget"]
