"""Co-design training on a tiny profile: schemes move the optics, resume, NaN guard, cache, export."""

import dataclasses
import json

import pytest
import torch

import lenses
from benchmark.codesign.codesigned_lenses import START_SPEC, attach
from benchmark.codesign.coefficients import INITIAL_AMPLITUDE_UM, bound_limited
from benchmark.codesign.data import CropSampler
from benchmark.codesign.schemes import SCHEMES
from benchmark.codesign.trainer import CoDesign, TrainingDivergedError
from benchmark.store.profiles import PROFILES
from lenses.spec import load_spec

pytestmark = pytest.mark.slow  # most tests train a co-design step or more (5-25 s each)

TINY = dataclasses.replace(PROFILES["smoke"], image_size=(64, 128), n_train=2, train_crop=(48, 48), batch_size=2,
                           codesign_steps=2, pretrain_steps=1, utility_model="tiny", adversary_width=4)


def run(scheme, tmp_path, profile=TINY, seed=0):
    return CoDesign(load_spec(START_SPEC), SCHEMES[scheme], profile, seed, "cpu", tmp_path)


@pytest.mark.parametrize("scheme", ["os", "os-d-1", "os-d-100", "os-d-1000", "os-d-mtadam", "gp", "gp-literal",
                                    "os-info"])
def test_one_step_of_each_scheme_moves_the_optics(scheme, tmp_path):
    profile = dataclasses.replace(TINY, codesign_steps=1)
    seen = {}
    trained = run(scheme, tmp_path, profile).train(progress=False, on_step=lambda step, stats: seen.update(stats))
    start = torch.tensor(trained.record["initial_coefficients_um"])
    moved = torch.tensor(trained.record["final_coefficients_um"])
    assert float((moved - start).abs().max()) > 1e-4
    assert trained.lens.spec.mask.bounds_um == load_spec(START_SPEC).mask.bounds_um
    if scheme.startswith("gp"):
        assert torch.isfinite(torch.tensor(seen["penalty"]))
    if scheme.startswith("os-d") or scheme.startswith("gp"):
        assert seen["lambda_deb"] > 0 and seen["grad_deb_norm"] > 0
    assert (trained.adversary is None) == (scheme in ("os", "os-info"))


def test_os_info_step_lowers_the_bound(tmp_path):
    from benchmark.scenes.plate_spectrum import cached_plate_spectrum
    from lenses.bound import noise_to_signal, plate_bits
    profile = dataclasses.replace(TINY, codesign_steps=2)
    trained = run("os-info", tmp_path, profile).train(progress=False)
    bits = trained.record["curves"]["bits"]
    spectrum = cached_plate_spectrum(tmp_path, profile.bound_scenes)
    lens = trained.lens
    final = float(plate_bits(lens.psf(), spectrum, 32, noise_to_signal(lens, spectrum.mean_radiance)))
    assert final < bits[0], (bits, final)


def test_gradient_penalty_reaches_the_optics():
    lens = lenses.Lens(load_spec(START_SPEC))
    from attacks.networks.red10 import RED10
    deb = RED10(4)
    x = torch.rand(2, 3, 32, 32)
    loss = torch.nn.functional.mse_loss(deb(lens(x, generator=torch.Generator().manual_seed(0))), x)
    (g,) = torch.autograd.grad(loss, lens.coefficients_um, create_graph=True)
    (g2,) = torch.autograd.grad((g.norm() - 1) ** 2, lens.coefficients_um)
    assert torch.isfinite(g2).all() and float(g2[1:].abs().sum()) > 0


def test_resume_after_interrupt_matches_uninterrupted(tmp_path):
    profile = dataclasses.replace(TINY, codesign_steps=3)
    whole = run("gp", tmp_path / "a", profile).train(progress=False)
    interrupted = run("gp", tmp_path / "b", profile)
    with pytest.raises(KeyboardInterrupt):
        interrupted.train(progress=False, stop_after=1)
    assert interrupted.checkpoint_path.is_file()
    assert not interrupted.directory.exists(), "no partial artifact after an interrupt"
    assert torch.load(interrupted.checkpoint_path, weights_only=True)["step"] == 1
    resumed = run("gp", tmp_path / "b", profile).train(progress=False)
    assert resumed.record["final_coefficients_um"] == whole.record["final_coefficients_um"]
    assert resumed.record["curves"]["step"] == [0, 1, 2]
    # The seeded start: not zero on the free terms, the same draw in both runs, written into the spec.
    start = resumed.record["initial_coefficients_um"]
    assert start == whole.record["initial_coefficients_um"]
    assert start[0] == 0.0 and all(0 < abs(c) <= INITIAL_AMPLITUDE_UM for c in start[1:])
    assert f"{start[3]:+.4f}" in resumed.lens.spec.description
    assert resumed.record["adversary"] == whole.record["adversary"]
    # The published curves hold each step once, also after the interruption.
    lines = (resumed.directory / "curves.jsonl").read_text().splitlines()
    assert [json.loads(line)["step"] for line in lines] == [0, 1, 2]
    assert json.loads(lines[2])["coefficients_um"] == resumed.record["final_coefficients_um"]
    assert not interrupted.live_dir.exists(), "the live curves are removed once published"


def test_nan_loss_stops_with_a_clear_message_and_keeps_the_checkpoint(tmp_path, monkeypatch):
    original = CropSampler.batch

    def poisoned(self, step, device="cpu"):
        x, y = original(self, step, device)
        return (x * float("nan"), y) if step == 1 else (x, y)

    monkeypatch.setattr(CropSampler, "batch", poisoned)
    r = run("os-d-1", tmp_path)
    with pytest.raises(TrainingDivergedError, match=r"diverged at step 1.*checkpoint"):
        r.train(progress=False)
    assert torch.load(r.checkpoint_path, weights_only=True)["step"] == 1
    assert not r.directory.exists()


def test_second_load_is_a_cache_hit_and_the_learned_lens_is_a_spec(tmp_path, monkeypatch):
    first = run("os-d-100", tmp_path).load_or_train(progress=False)
    monkeypatch.setattr(CoDesign, "train", lambda *a, **k: pytest.fail("trained again despite the cache"))
    again = run("os-d-100", tmp_path).load_or_train(progress=False)
    assert again.record["final_coefficients_um"] == first.record["final_coefficients_um"]
    exported = lenses.load(str(first.directory / "lens.toml"))
    assert list(exported.spec.mask.zernike_um) == pytest.approx(first.record["final_coefficients_um"], abs=1e-7)
    torch.testing.assert_close(exported.psf(), first.lens.psf())


def test_fixed_scheme_needs_no_bounds_and_optics_schemes_do(tmp_path):
    fixed = CoDesign(lenses.load("defocus").spec, SCHEMES["fixed"], TINY, 0, "cpu", tmp_path)
    assert fixed.load_or_train(progress=False).adversary is None
    with pytest.raises(ValueError, match="declares no mask.bounds_um"):
        CoDesign(lenses.load("defocus").spec, SCHEMES["gp"], TINY, 0, "cpu", tmp_path)


def test_eval_keeps_the_training_record(tmp_path):
    trained = run("os", tmp_path, dataclasses.replace(TINY, codesign_steps=1)).train(progress=False)
    lens = attach(trained)
    assert lens.training_record is trained.record
    lens.eval()
    assert lens.training is False, "torch's train/eval flag is its own attribute"
    assert lens.training_record is trained.record
    lens.train()
    assert lens.training is True and lens.training_record["scheme"] == "os"


def test_bound_limited_names_the_coefficients_on_a_bound():
    bounds = ((0.0, 0.0), (-0.5, 0.5), (-0.5, 0.5), (-1.0, 1.0), (-1.0, 1.0), (-1.0, 1.0))
    assert bound_limited([0.0, 0.1, -0.2, 0.3, 0.0, -0.5], bounds) == []   # piston is frozen, not limited
    assert bound_limited([0.0, 0.5, -0.495, 0.97, -1.0, 0.0], bounds) == [2, 3, 5]
    assert bound_limited([0.0, 0.0, 0.0, 0.985, 0.0, 0.0], bounds) == [4]   # 0.015 um: within 1 % of [-1, 1]
    assert bound_limited([0.0, 0.0, 0.0, 0.97, 0.0, 0.0], bounds) == []


def test_record_flags_a_lens_that_ends_on_its_bounds(tmp_path):
    # Adam's first step is lr x sign(gradient) per coefficient: lr 5 um throws every free term onto a bound.
    thrown = dataclasses.replace(TINY, codesign_steps=1, optics_lr=5.0)
    pinned = run("os", tmp_path / "pinned", thrown).train(progress=False)
    assert pinned.record["bound_limited"] is True
    assert pinned.record["bound_limited_terms"] == ["Z2 tilt x", "Z3 tilt y", "Z4 defocus", "Z5 astigmatism 45",
                                                    "Z6 astigmatism 0"]
    free = run("os", tmp_path / "free", dataclasses.replace(TINY, codesign_steps=1)).train(progress=False)
    assert free.record["bound_limited"] is False and free.record["bound_limited_terms"] == []
    assert free.record["max_sag_um"] == load_spec(START_SPEC).mask.max_sag_um


def test_curves_are_written_as_json_lines_tensorboard_events_and_a_chart(tmp_path):
    from tensorboard.backend.event_processing.event_accumulator import EventAccumulator
    trained = run("gp", tmp_path).train(progress=False)
    d = trained.directory
    entries = [json.loads(line) for line in (d / "curves.jsonl").read_text().splitlines()]
    assert [e["step"] for e in entries] == list(range(TINY.codesign_steps))
    for key in ("seg", "deb", "penalty", "grad_seg_norm", "grad_deb_norm", "grad_penalty_norm", "lambda_deb",
                "psf_radius_px", "coefficients_um"):
        assert all(key in e for e in entries), key
    events = EventAccumulator(str(d / "tensorboard")).Reload()
    penalty = events.Scalars("loss/penalty")
    assert [e.step for e in penalty] == [0, 1]
    assert [e.value for e in penalty] == pytest.approx([e["penalty"] for e in entries], rel=1e-6)
    assert {"loss/L_seg", "loss/L_deb", "grad_norm/seg", "grad_norm/deb", "lambda/deb", "psf_radius_px",
            "coefficients_um/Z4 defocus"} <= set(events.Tags()["scalars"])
    assert (d / "curves.png").read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"


def test_the_utility_net_is_trained_on_white_balanced_sensor_images(tmp_path, monkeypatch):
    """Every image the co-design segments is a white-balanced sensor image (the sensor's tint is the
    camera's, not something the utility net must learn), while the adversary keeps the raw one."""
    from benchmark.codesign import trainer as trainer_module
    balanced, segmented = [], []
    original_balance, original_logits = lenses.Lens.white_balance, trainer_module.segment_logits

    def balance_spy(self, sensor):
        out = original_balance(self, sensor)
        balanced.append((sensor.detach().clone(), out.detach().clone()))
        return out

    def logits_spy(net, images):
        segmented.append(images.detach().clone())
        return original_logits(net, images)

    monkeypatch.setattr(lenses.Lens, "white_balance", balance_spy)
    monkeypatch.setattr(trainer_module, "segment_logits", logits_spy)
    run("os-d-1", tmp_path, dataclasses.replace(TINY, codesign_steps=1)).train(progress=False)
    assert segmented and balanced
    outputs = [out for _, out in balanced]
    assert all(any(torch.equal(seen, out) for out in outputs) for seen in segmented)
    sensor, out = balanced[0]
    assert not torch.allclose(sensor, out)  # the sensor is tinted: balancing changes it


def test_white_balance_is_what_the_identity_attacker_returns():
    import attacks
    from attacks.base import FitContext
    lens = lenses.Lens(load_spec(START_SPEC))
    sensor = torch.rand(2, 3, 16, 24)
    identity = attacks.load("identity")
    identity.fit(FitContext(lens=lens, device="cpu"))
    assert torch.equal(identity.restore(sensor), lens.white_balance(sensor))
    expected = (sensor / lens.gain().view(1, 3, 1, 1)).clamp(0, 1)
    assert torch.allclose(lens.white_balance(sensor), expected) and float(lens.white_balance(sensor).max()) <= 1.0
