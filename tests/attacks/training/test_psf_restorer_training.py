"""Pre-training of the known-PSF restorer (attacks/training/psf_restorer_training.py), on the small budget."""

from __future__ import annotations

import dataclasses

import pytest
import torch

from attacks.backends.real_fft import OtfCache
from attacks.training import psf_restorer_training as training
from attacks.training.lens_family import FamilyLens, LensFamily
from attacks.training.psf_restorer_training import PSF_BUDGETS, PsfPretrainBudget, build_network, pretrain, psf_inputs
from benchmark.runner.sensing import to_tensor
from benchmark.scenes.loading import load_scenes

SMALL = PSF_BUDGETS["small"]


@pytest.fixture(scope="module")
def scenes() -> tuple[torch.Tensor, torch.Tensor]:
    return (to_tensor(load_scenes("synthetic", "train", 3, (64, 128), 0)),
            to_tensor(load_scenes("synthetic", "test", 1, (64, 128), 0)))


def _state(net: torch.nn.Module) -> dict[str, torch.Tensor]:
    return {k: v.clone() for k, v in net.state_dict().items()}


def test_the_untrained_network_returns_the_wiener_estimate(scenes):
    family = LensFamily()
    lens = family.build(FamilyLens("mask", (0.0, 0.5, -0.5, 1.0, -1.0, 1.0), 10.0))
    with torch.no_grad():
        sensor = lens(scenes[0][:1], generator=torch.Generator().manual_seed(0))
        x = psf_inputs(sensor, OtfCache(lens.psf()), lens.gain())
        out = build_network(SMALL, 0)(x)
    assert x.shape == (1, 6, 64, 128)
    assert torch.equal(out, x[:, :3])


def test_pretraining_is_deterministic_and_keeps_the_best_evaluation(scenes):
    train, heldout = scenes
    a, curve_a = pretrain(SMALL, train, heldout, 0)
    b, curve_b = pretrain(SMALL, train, heldout, 0)
    assert all(torch.equal(a.state_dict()[k], v) for k, v in b.state_dict().items())
    assert curve_a.heldout_psnr_db == curve_b.heldout_psnr_db
    assert curve_a.steps == list(range(SMALL.eval_every, SMALL.max_steps + 1, SMALL.eval_every))[:len(curve_a.steps)]
    assert curve_a.kept_step == curve_a.steps[max(range(len(curve_a.steps)), key=curve_a.heldout_psnr_db.__getitem__)]
    assert curve_a.to_fit_curve().kept_step == curve_a.kept_step
    c, _ = pretrain(SMALL, train, heldout, 1)
    assert any(not torch.equal(c.state_dict()[k], v) for k, v in a.state_dict().items())


def test_an_interrupted_pretraining_resumes_to_the_same_weights(scenes, tmp_path):
    train, heldout = scenes
    budget = dataclasses.replace(SMALL, patience_evals=99)  # no early stop: every evaluation is reached
    whole, whole_curve = pretrain(budget, train, heldout, 0)
    checkpoint = tmp_path / "ckpt.pt"
    seen: list[str] = []

    def interrupt(line: str) -> None:
        seen.append(line)
        if len(seen) == 2:
            raise KeyboardInterrupt

    with pytest.raises(KeyboardInterrupt):
        pretrain(budget, train, heldout, 0, checkpoint=checkpoint, progress=interrupt)
    assert torch.load(checkpoint, weights_only=True)["step"] == 2 * budget.eval_every
    resumed, resumed_curve = pretrain(budget, train, heldout, 0, checkpoint=checkpoint)
    assert resumed_curve.steps == whole_curve.steps
    assert resumed_curve.heldout_psnr_db == pytest.approx(whole_curve.heldout_psnr_db, abs=1e-5)
    for k, v in whole.state_dict().items():
        assert torch.allclose(resumed.state_dict()[k], v, atol=1e-6), k


def test_the_patience_rule():
    assert training._flattened([20.0, 21.0, 21.01, 21.02], 2, 0.05) == (True, False)
    assert training._flattened([20.0, 21.0, 21.5, 21.9], 2, 0.05) == (False, True)
    assert training._flattened([20.0, 21.0], 2, 0.05) == (False, True)  # too short to tell: still rising


def test_a_bad_budget_names_its_field():
    with pytest.raises(ValueError, match="crop_px must be even"):
        dataclasses.replace(SMALL, crop_px=33)
    with pytest.raises(ValueError, match="PsfPretrainBudget.max_steps"):
        PsfPretrainBudget(**{**SMALL.to_dict(), "max_steps": 0})


def test_cosine_cycles_continue_from_the_first_cycles_weights_at_the_restart(scenes):
    """A two-cycle budget warm-started from its first cycle's fit: the curve goes on from that fit's
    (same held-out set, so the first cycle's scores are kept as they were), the learning rate restarts at the
    cycle's end, the second cycle trains (weights change), and the run is a function of its inputs."""
    train, heldout = scenes
    two = dataclasses.replace(SMALL, max_steps=8, cycle_steps=4, patience_evals=99)
    first_budget = two.first_cycles()
    assert first_budget is not None and (first_budget.max_steps, first_budget.cycle_steps) == (4, 0)
    assert "cycle_steps" not in first_budget.to_dict() and two.to_dict()["cycle_steps"] == 4  # old keys stay valid
    first, first_curve = pretrain(first_budget, train, heldout, 0)
    runs = [pretrain(two, train, heldout, 0, warm_start=(_state(first), first_curve)) for _ in range(2)]
    (net, curve), (again, curve_again) = runs
    assert curve.steps == [4, 8] and curve.heldout_psnr_db[0] == pytest.approx(first_curve.heldout_psnr_db[-1])
    assert curve.heldout_psnr_db == curve_again.heldout_psnr_db
    assert all(torch.equal(again.state_dict()[k], v) for k, v in net.state_dict().items())
    kept_first = curve.kept_step == 4
    assert kept_first == all(torch.equal(net.state_dict()[k], v) for k, v in first.state_dict().items())
    with pytest.raises(ValueError, match="cycle's end"):
        pretrain(two, train, heldout, 0, warm_start=(_state(first), dataclasses.replace(first_curve, steps=[2],
                                                                                        heldout_psnr_db=[1.0])))


def test_with_cycles_the_stop_rule_is_read_at_a_cycles_end_only():
    with pytest.raises(ValueError, match="cycle_steps=3 must divide max_steps"):
        dataclasses.replace(SMALL, cycle_steps=3)  # 12 steps, evaluations every 4
    with pytest.raises(ValueError, match="multiple of eval_every"):
        dataclasses.replace(SMALL, max_steps=12, cycle_steps=6)
    assert dataclasses.replace(SMALL, max_steps=24, cycle_steps=12).first_cycles().to_dict() == \
        dataclasses.replace(SMALL, max_steps=12).to_dict()


def _fine_tune_case(scenes, min_gain_db: float) -> tuple[torch.nn.Module, training.PretrainCurve]:
    train, heldout = scenes
    lens = LensFamily().build(FamilyLens("mask", (0.0, 0.5, -0.5, 1.0, -1.0, 1.0), 10.0))
    with torch.no_grad():
        otf, gain = OtfCache(lens.psf()), lens.gain()
        inputs = psf_inputs(lens(train, generator=torch.Generator().manual_seed(0)), otf, gain)
        held = psf_inputs(lens(heldout, generator=torch.Generator().manual_seed(1)), otf, gain)
    net = build_network(SMALL, 0)
    curve = training.fine_tune(net, inputs, train, held, heldout, max_steps=25, crop_px=32, batch_size=2, seed=0,
                               min_gain_db=min_gain_db)
    return net, curve


def test_a_fine_tune_keeps_its_start_unless_a_step_beats_it_by_the_stop_rules_gain(scenes):
    # The untrained network is the Wiener estimate; 25 steps move it. With no threshold the better step is kept.
    tuned, curve = _fine_tune_case(scenes, 0.0)
    start, after = curve.heldout_psnr_db
    assert curve.steps == [0, 25] and after > start, "the 25 steps did not gain: the test proves nothing"
    assert curve.kept_step == 25
    # A threshold just above that gain: the same steps (deterministic), and the start handed back unchanged.
    kept, curve_b = _fine_tune_case(scenes, after - start + 0.01)
    assert curve_b.heldout_psnr_db == curve.heldout_psnr_db
    assert curve_b.kept_step == 0 and curve_b.to_fit_curve().kept_step == 0
    assert all(torch.equal(kept.state_dict()[k], v) for k, v in build_network(SMALL, 0).state_dict().items())
    assert any(not torch.equal(tuned.state_dict()[k], v) for k, v in kept.state_dict().items())


def test_a_warm_start_onto_near_sharp_lenses_scores_its_start_on_the_new_held_out_set(scenes):
    """The cycle that brings in near-sharp lenses: the earlier cycles' budget has none (its key is the one
    shipped before), the held-out set gains near-sharp lenses, so the start is scored again on it and the
    earlier curve is kept whole in ``before``; each evaluation keeps the mean over either kind of lens."""
    train, heldout = scenes
    two = dataclasses.replace(SMALL, max_steps=8, cycle_steps=4, patience_evals=99, sharp_share=0.5, sharp_from=4,
                              heldout_sharp=1)
    first_budget = two.first_cycles()
    assert first_budget is not None and first_budget.to_dict() == dataclasses.replace(SMALL, max_steps=4, patience_evals=99).to_dict()
    assert two.to_dict()["heldout_sharp"] == 1 and two.family().sharp_share == 0.5
    first, first_curve = pretrain(first_budget, train, heldout, 0)
    start_again = pretrain(dataclasses.replace(first_budget, max_steps=8, cycle_steps=4, patience_evals=99),
                           train, heldout, 0, warm_start=(_state(first), first_curve))[1]
    net, curve = pretrain(two, train, heldout, 0, warm_start=(_state(first), first_curve))
    assert curve.before is not None and curve.before["heldout_psnr_db"] == first_curve.heldout_psnr_db
    assert curve.steps == [4, 8] and len(curve.heldout) == SMALL.heldout_lenses + 1
    assert curve.heldout[:SMALL.heldout_lenses] == first_curve.heldout
    # The start on the lenses both sets share scores as before; the mean over all is the lens-weighted mean.
    assert curve.others_psnr_db[0] == pytest.approx(first_curve.heldout_psnr_db[-1], abs=1e-5)
    n = SMALL.heldout_lenses
    for total, others, sharp in zip(curve.heldout_psnr_db, curve.others_psnr_db, curve.sharp_psnr_db):
        assert total == pytest.approx((n * others + sharp) / (n + 1), abs=1e-5)
    assert start_again.before is None  # the same held-out set: the curve simply goes on
