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
