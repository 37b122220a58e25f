"""training-adversary: uses the co-designed lens's RED10, and is skipped for fixed lenses."""

from __future__ import annotations

import pytest
import torch

import attacks
from attacks.networks import RED10


@pytest.fixture
def codesigned_lens(fake_lens):
    torch.manual_seed(0)
    fake_lens.adversary = RED10(width=4)
    return fake_lens


@pytest.mark.parametrize("backend", ["torch", "onnx"])
def test_restores_with_the_lens_adversary(codesigned_lens, backend):
    attack = attacks.load("training-adversary", backend=backend)
    ctx = attacks.FitContext(lens=codesigned_lens, adversary=codesigned_lens.adversary)
    assert attack.skip_reason(ctx) is None
    attack.fit(ctx)
    sensor = torch.rand(2, 3, 40, 56, generator=torch.Generator().manual_seed(1))
    with torch.no_grad():
        expected = codesigned_lens.adversary(sensor).clamp(0, 1)
    torch.testing.assert_close(attack.restore(sensor), expected, atol=1e-4, rtol=0)
    assert attack.describe()["network"] == "RED10"


def test_runs_through_onnx_runtime_by_default_and_torch_when_the_export_fails(codesigned_lens, monkeypatch):
    ctx = attacks.FitContext(lens=codesigned_lens, adversary=codesigned_lens.adversary)
    sensor = torch.rand(1, 3, 24, 40, generator=torch.Generator().manual_seed(2))
    with torch.no_grad():
        expected = codesigned_lens.adversary(sensor).clamp(0, 1)
    attack = attacks.load("training-adversary")
    attack.fit(ctx)
    assert attack.engine.backend == "onnx" and attack.describe()["backend"] == "onnx"

    def broken_export(*_args, **_kwargs):
        raise RuntimeError("operator not supported")

    monkeypatch.setattr("attacks.backends.onnx_runtime.export_onnx", broken_export)
    fallback = attacks.load("training-adversary")
    fallback.fit(ctx)
    assert fallback.engine.backend == "torch"
    assert "operator not supported" in fallback.engine.describe()["fallback_reason"]
    for a in (attack, fallback):
        torch.testing.assert_close(a.restore(sensor), expected, atol=1e-4, rtol=0)


def test_scores_a_frozen_copy(codesigned_lens):
    attack = attacks.load("training-adversary", backend="torch")
    attack.fit(attacks.FitContext(lens=codesigned_lens, adversary=codesigned_lens.adversary))
    sensor = torch.rand(1, 3, 32, 32)
    before = attack.restore(sensor)
    with torch.no_grad():
        for p in codesigned_lens.adversary.parameters():
            p.add_(1.0)
    torch.testing.assert_close(attack.restore(sensor), before, atol=0, rtol=0)


def test_fixed_lens_is_skipped_with_a_reason(fake_lens):
    attack = attacks.load("training-adversary")
    ctx = attacks.FitContext(lens=fake_lens)
    reason = attack.skip_reason(ctx)
    assert reason and "adversary" in reason
    with pytest.raises(attacks.MissingRequirementError, match="adversary"):
        attack.fit(ctx)
