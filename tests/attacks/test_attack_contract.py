"""One contract for every registered attacker (the timm pattern): a new plugin gets it free."""

from __future__ import annotations

import dataclasses
import json

import pytest
import torch

import attacks
from attacks.networks import RED10

REGISTERED = sorted(attacks.available())


def segment(images):
    """A segmenter that calls everything a car (train id 13), for readers that find vehicles with one."""
    return torch.full((images.shape[0], *images.shape[-2:]), 13, dtype=torch.long)


@pytest.fixture
def context(fake_lens, tmp_path):
    """Every field of the typed context set, the budget the tiny default: what any attacker may ask for."""
    def pairs():
        g = torch.Generator().manual_seed(0)
        sharp = torch.rand(2, 3, 32, 32, generator=g)
        yield sharp * 0.5, sharp

    return attacks.FitContext(lens=fake_lens, train_pairs=pairs, cache_dir=tmp_path, device="cpu", seed=0,
                              segmenter=segment, adversary=RED10(width=4))


def test_the_context_is_typed_fields_only():
    fields = {f.name: f.type for f in dataclasses.fields(attacks.FitContext)}
    assert set(fields) == {"lens", "train_pairs", "cache_dir", "artifacts", "device", "seed", "budget", "segmenter",
                           "plate_format", "adversary"}
    assert not any(t in ("object", "Any", "dict[str, Any]") for t in fields.values()), fields
    assert attacks.FitContext().budget == attacks.AttackBudget(profile="tiny")


@pytest.mark.parametrize("name", REGISTERED)
def test_attack_contract(name, context):
    attack = attacks.load(name)
    assert isinstance(attack, attacks.Attack) and attack.name == name
    assert isinstance(attack.threat_model, attacks.ThreatModel)
    assert set(attack.requires) <= {f.name for f in dataclasses.fields(attacks.FitContext)}
    reason = attack.skip_reason(context)
    assert reason is None or (isinstance(reason, str) and reason)
    if reason is None:
        report = attack.fit(context)
        assert isinstance(report, attacks.FitReport)
        assert report.still_rising in (None, True, False)
        assert all(isinstance(k, str) and v >= 0 for k, v in report.stage_seconds.items())
        if report.curve is not None:
            assert len(report.curve.steps) == len(report.curve.scores) and report.curve.kept_step in report.curve.steps
    description = attack.describe()
    assert description["name"] == name
    json.dumps(description)  # provenance must be serializable


@pytest.mark.parametrize("name", REGISTERED)
def test_restorer_contract(name, context):
    attack = attacks.load(name)
    if not isinstance(attack, attacks.Restorer):
        pytest.skip(f"{name} is not a restorer")
    if attack.skip_reason(context):
        pytest.skip(f"{name} does not apply to the fake lens: {attack.skip_reason(context)}")
    attack.fit(context)
    sensor = torch.rand(2, 3, 40, 56, generator=torch.Generator().manual_seed(1))
    with torch.no_grad():
        first, second = attack.restore(sensor), attack.restore(sensor.clone())
    assert first.shape == sensor.shape and first.dtype == sensor.dtype
    assert first.min() >= 0 and first.max() <= 1
    assert torch.equal(first, second)


@pytest.mark.parametrize("name", REGISTERED)
def test_reader_contract(name, context):
    """`read` returns one list of PlateRead per image, boxes of 4 numbers, scores in [0, 1]."""
    attack = attacks.load(name)
    if not isinstance(attack, attacks.Reader):
        pytest.skip(f"{name} is not a reader")
    if attack.skip_reason(context):
        pytest.skip(f"{name} does not apply to the fake lens: {attack.skip_reason(context)}")
    attack.fit(context)
    images = torch.rand(3, 3, 64, 96, generator=torch.Generator().manual_seed(2))
    hints = attacks.ReadHints(vehicle_boxes=[[(0.0, 0.0, 96.0, 64.0)]] * 3, segment=segment)
    with torch.no_grad():
        reads = attack.read(images, hints)
    assert isinstance(reads, list) and len(reads) == 3
    for per_image in reads:
        assert isinstance(per_image, list)
        for read in per_image:
            assert isinstance(read, attacks.PlateRead) and isinstance(read.text, str)
            assert len(read.box_xyxy) == 4 and 0.0 <= read.score <= 1.0
