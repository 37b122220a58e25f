"""The learned reader's pre-training across the lens family: deterministic per seed, resumable exactly,
held-out lenses apart from the training draws; and a fine-tune that evaluates its start keeps it when
training cannot beat it."""

from __future__ import annotations

import dataclasses

import pytest
import torch

from attacks.readers.learned_reader import LearnedReader
from attacks.training.lens_family import LensFamily
from attacks.training.plate_reader_training import ReaderBudget, held_out_set, train_reader
from attacks.training.psf_restorer_training import stream_generator
from attacks.training.reader_family_training import HELDOUT_SEED_OFFSET, FamilyBudget, pretrain_family

FMT = "LLDDDLL"
TINY = FamilyBudget(ReaderBudget(max_steps=4, batch_size=8, lr=1e-3, widths_px=(24.0, 64.0), eval_every=2,
                                 eval_plates=2, patience=5, bands_per_batch=2), heldout_lenses=2)


def fresh() -> torch.nn.Module:
    return LearnedReader.build(FMT, 0)


def weights(net: torch.nn.Module) -> dict[str, torch.Tensor]:
    return {k: v.clone() for k, v in net.state_dict().items()}


def last_weights(seed: int, folder) -> tuple[dict[str, torch.Tensor], object, list]:
    """The weights after the last step (the checkpoint's; the kept ones may be the start's), the curve
    and the held-out lenses of a TINY pre-training of a fresh network."""
    checkpoint = folder / f"s{seed}-{len(list(folder.iterdir()))}.pt"
    curve, held = pretrain_family(fresh(), FMT, seed, TINY, checkpoint=checkpoint)
    return torch.load(checkpoint, weights_only=True)["net"], curve, held


def test_a_pretraining_is_a_function_of_its_seed_and_evaluates_its_start(tmp_path):
    a, curve_a, held_a = last_weights(0, tmp_path)
    b, curve_b, held_b = last_weights(0, tmp_path)
    c, _, held_c = last_weights(1, tmp_path)
    assert curve_a.steps == [0, 2, 4] and curve_a.accuracy == curve_b.accuracy and held_a == held_b
    assert all(torch.equal(a[k], b[k]) for k in a)
    assert not all(torch.equal(a[k], c[k]) for k in a) and held_c != held_a
    assert len(held_a) == 2 and curve_a.stopped == "budget"


def test_a_resumed_pretraining_continues_exactly(tmp_path):
    whole = fresh()
    pretrain_family(whole, FMT, 0, TINY)

    class Stop(Exception):
        pass

    def stop_after_step_2(line: str) -> None:  # called after the evaluation's checkpoint is written
        if line.startswith("step 2/"):
            raise Stop

    checkpoint = tmp_path / "family.pt"
    try:
        pretrain_family(fresh(), FMT, 0, TINY, checkpoint=checkpoint, progress=stop_after_step_2)
    except Stop:
        pass
    resumed = fresh()
    curve, _ = pretrain_family(resumed, FMT, 0, TINY, checkpoint=checkpoint)
    assert curve.steps == [0, 2, 4]
    assert all(torch.equal(x, y) for x, y in zip(whole.state_dict().values(), resumed.state_dict().values()))


def test_the_held_out_lenses_are_not_training_draws():
    family = LensFamily()
    held = [family.draw(stream_generator(0, HELDOUT_SEED_OFFSET, i)).describe() for i in range(6)]
    trained = [family.draw(stream_generator(0, step)).describe() for step in range(500)]
    assert not any(h == t for h in held for t in trained)


def test_a_fine_tune_that_cannot_beat_its_start_keeps_it():
    """Injected fault: training plates through a camera that returns noise. The shipped sharp start,
    evaluated first on clean plates, reads them; the noise fit cannot beat it, so the start is kept."""
    from attacks.readers.learned_reader import pretrained_key, unpack_weights
    from attacks.training.shipped_weights import find_shipped

    def noise(x: torch.Tensor, generator: torch.Generator) -> torch.Tensor:
        return torch.rand(x.shape, generator=generator)

    budget = ReaderBudget(max_steps=4, batch_size=8, lr=1e-2, widths_px=(32.0, 64.0), eval_every=2, eval_plates=8,
                          patience=5, bands_per_batch=2, eval_start=True)
    net = fresh()
    unpack_weights(net, find_shipped(LearnedReader.name, pretrained_key(FMT)).data)
    start = weights(net)
    held = held_out_set(None, budget, 0.0, 0, FMT, 0)
    curve = train_reader(net, [noise], budget, 0.0, 0, FMT, 0, held)
    assert curve.steps == [0, 2, 4] and curve.accuracy[0] > 0.8 > max(curve.accuracy[1:])
    assert curve.best_step == 0 and all(torch.equal(start[k], v) for k, v in net.state_dict().items())
    assert "eval_start" in budget.to_dict() and "eval_start" not in dataclasses.replace(budget, eval_start=False).to_dict()


def test_the_wiener_camera_brings_a_drawn_lens_s_image_closer_to_the_scene_and_cuts_no_blur_margin():
    """reads="wiener": the patch the reader is trained on is the Wiener estimate with the drawn lens's PSF and
    gain, nearer the sharp scene than the sensor image is (the blurring lens of the family's first draw), and
    its crops hold no blur margin; "sensor" keeps the spread."""
    from attacks.training.reader_family_training import family_camera

    family = LensFamily()
    drawn = family.draw(stream_generator(0, 3))
    sensor, wiener = family_camera(family, drawn, "sensor"), family_camera(family, drawn, "wiener")
    assert wiener.spread_px == 0.0 < sensor.spread_px and wiener.psf_half_px == sensor.psf_half_px
    g = torch.Generator().manual_seed(0)
    scene = torch.zeros(1, 3, 96, 96)
    scene[..., 24:72, ::8] = 0.9  # bars: detail the lens blurs
    scene[..., 24:72, 1::8] = 0.9
    scene += 0.05
    seen, estimate = sensor.camera(scene, torch.Generator().manual_seed(1)), wiener.camera(scene, g)
    gain = family.build(drawn).gain().detach().view(1, 3, 1, 1)
    inner = (..., slice(16, 80), slice(16, 80))
    error_sensor = ((seen / gain).clamp(0, 1) - scene)[inner].pow(2).mean()
    error_wiener = (estimate - scene)[inner].pow(2).mean()
    assert error_wiener < 0.7 * error_sensor, (float(error_wiener), float(error_sensor))


def test_an_unknown_input_is_refused_with_the_valid_ones():
    from attacks.training.reader_family_training import family_camera

    family = LensFamily()
    with pytest.raises(ValueError, match="sensor, wiener"):
        family_camera(family, family.draw(stream_generator(0, 0)), "restored")


def test_a_wiener_pretraining_is_a_function_of_its_seed(tmp_path):
    a, b = fresh(), fresh()
    curve_a, _ = pretrain_family(a, FMT, 0, TINY, reads="wiener")
    curve_b, _ = pretrain_family(b, FMT, 0, TINY, reads="wiener")
    assert curve_a.accuracy == curve_b.accuracy
    assert all(torch.equal(x, y) for x, y in zip(a.state_dict().values(), b.state_dict().values()))
