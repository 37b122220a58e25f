"""learned-reader: its simulation, crops, training stop rule, shipped start, determinism and cache."""

from __future__ import annotations

import dataclasses
import math

import numpy as np
import pytest
import torch

import attacks
import lenses
from attacks.readers.learned_reader import LearnedReader, pretrained_key
import attacks.training.plate_reader_training as reader_training
from attacks.training.plate_reader_training import (FitCurve, ReaderBudget, flattened, held_out_gain, plate_accuracy, train_reader,
                                         training_batch, width_bands)
from common.plate_render import PLATE_FORMAT
from attacks.readers.plates.plate_sim import (CROP_HW, crop_margin_px, plate_crops, psf_radius_px, psf_support_px,
                                             simulate_plates)
from attacks.training.shipped_weights import find_shipped


class MemoryStore:
    """An ``ArtifactStore`` in a dict (the benchmark's cache implements the same two calls)."""

    def __init__(self) -> None:
        self.items: dict[str, bytes] = {}

    def load(self, kind, key):
        return self.items.get(f"{kind}:{sorted(key.items())!r}")

    def save(self, kind, key, data):
        self.items[f"{kind}:{sorted(key.items())!r}"] = data


def test_psf_radius_of_a_gaussian_is_the_rayleigh_quantile(make_gaussian_psf):
    # The radius of a 2-D Gaussian (sigma) holding a fraction E of its light: sigma sqrt(-2 ln(1 - E)).
    sigma = 3.0
    psf = make_gaussian_psf(sigma, 20, torch.float64)
    for energy in (0.5, 0.8):
        assert psf_radius_px(psf, energy) == pytest.approx(sigma * math.sqrt(-2 * math.log(1 - energy)), abs=0.35)


def test_psf_support_is_the_square_ring_that_holds_the_light_around_the_centre():
    k = 21
    delta = torch.zeros(3, k, k, dtype=torch.float64)
    delta[:, k // 2, k // 2] = 1.0
    assert psf_support_px(delta) == 0
    # A uniform square of half-width 4: 0.995 of its light is inside ring 4, not inside ring 3 (49/81).
    box = torch.zeros(3, k, k, dtype=torch.float64)
    box[:, k // 2 - 4:k // 2 + 5, k // 2 - 4:k // 2 + 5] = 1.0 / 81
    assert psf_support_px(box) == 4 and psf_support_px(box, 0.5) == 3
    # Light moved off the centre (a tilt) counts by how far it went, in the colour that moved furthest.
    shifted = delta.clone()
    shifted[2] = 0.0
    shifted[2, k // 2 + 3, k // 2 - 7] = 1.0
    assert psf_support_px(shifted) == 7
    # Never beyond half the support, even where light sits in the corner.
    corner = torch.zeros(3, k, k, dtype=torch.float64)
    corner[:, 0, 0] = 1.0
    assert psf_support_px(corner) == k // 2


def test_crop_of_a_box_the_size_of_the_input_is_the_region_itself():
    # A box whose grown size is exactly CROP_HW, on whole pixels: RoIAlign samples pixel centres, so the
    # crop is that region, standardised per channel.
    h, w = CROP_HW
    spread = 2.0
    # grow (bw, bh) by the margin to (w, h): bw + 2 (0.15 bw + s) = w, bh + 2 (0.3 bh + s) = h
    bw, bh = (w - 2 * spread) / 1.3, (h - 2 * spread) / 1.6
    image = torch.rand(1, 3, 60, 160, generator=torch.Generator().manual_seed(0))
    mx, my = crop_margin_px((bw, bh), spread)
    x0, y0 = 10 + mx, 7 + my
    crop = plate_crops(image, [(0, (x0, y0, x0 + bw, y0 + bh))], spread)[0]
    region = image[0, :, 7:7 + h, 10:10 + w]
    expected = (region - region.mean(dim=(1, 2), keepdim=True)) / (region.std(dim=(1, 2), keepdim=True) + 1e-3)
    torch.testing.assert_close(crop, expected, atol=1e-4, rtol=1e-4)


def test_simulation_is_a_function_of_its_seeds_and_labels_spell_the_text():
    def batch(seed):
        return simulate_plates(None, 6, (30, 60), np.random.default_rng(seed), torch.Generator().manual_seed(seed),
                               0.0, PLATE_FORMAT)
    a, b, c = batch(1), batch(1), batch(2)
    assert torch.equal(a.crops, b.crops) and a.texts == b.texts
    assert a.texts != c.texts
    assert a.crops.shape == (6, 3, *CROP_HW)
    letters, digits = "ABCDEFGHIJKLMNOPQRSTUVWXYZ", "0123456789"
    for text, label in zip(a.texts, a.labels.tolist()):
        assert "".join((letters if f == "L" else digits)[i] for f, i in zip(PLATE_FORMAT, label)) == text
    assert all(28 <= w <= 63 for w in a.widths_px)


def test_a_training_batch_draws_an_equal_part_from_each_log_spaced_band(monkeypatch):
    budget = ReaderBudget(max_steps=1, batch_size=10, lr=1e-3, widths_px=(8.0, 200.0), eval_every=1, eval_plates=1,
                          patience=1, bands_per_batch=4)
    bands = width_bands(budget)
    assert bands[0][0] == pytest.approx(8.0) and bands[-1][1] == pytest.approx(200.0)
    assert all(a[1] == pytest.approx(b[0]) for a, b in zip(bands, bands[1:]))           # contiguous
    assert {round(math.log(hi / lo), 9) for lo, hi in bands} == {round(math.log(25) / 4, 9)}  # equal log ratios
    calls = []

    def spy(camera, n, widths_px, *args, **kwargs):
        batch = simulate_plates(camera, n, widths_px, *args, **kwargs)
        calls.append((n, widths_px, batch.widths_px))
        return batch
    monkeypatch.setattr(reader_training, "simulate_plates", spy)
    crops, labels = training_batch(None, budget, np.random.default_rng(0), torch.Generator().manual_seed(0), 0.0,
                                   PLATE_FORMAT, 0)
    assert [n for n, _, _ in calls] == [3, 3, 2, 2] and crops.shape[0] == labels.shape[0] == 10
    assert [band for _, band, _ in calls] == bands
    for _, (lo, hi), widths in calls:                    # each plate within its band (+-5 % per plate, rounded)
        assert all(0.95 * lo - 1 <= w <= 1.05 * hi + 1 for w in widths)
    again = training_batch(None, budget, np.random.default_rng(0), torch.Generator().manual_seed(0), 0.0, PLATE_FORMAT, 0)
    assert torch.equal(again[0], crops) and torch.equal(again[1], labels)


def test_bands_per_batch_is_checked_and_left_out_of_keys_made_before_it():
    one = dict(max_steps=1, batch_size=4, lr=1e-3, widths_px=(8.0, 200.0), eval_every=1, eval_plates=1, patience=1)
    assert "bands_per_batch" not in ReaderBudget(**one).to_dict()
    assert ReaderBudget(**one, bands_per_batch=4).to_dict()["bands_per_batch"] == 4
    with pytest.raises(ValueError, match="bands_per_batch=5"):
        ReaderBudget(**one, bands_per_batch=5)


def test_the_stop_rule_flattens_and_flags_a_rising_fit():
    budget = ReaderBudget(max_steps=10, batch_size=2, lr=1e-3, widths_px=(30, 60), eval_every=1, eval_plates=1,
                          patience=2, min_gain=0.01)
    assert held_out_gain([0.1, 0.5, 0.5, 0.505], 2) == pytest.approx(0.005)
    assert flattened([0.1, 0.5, 0.5, 0.505], budget)        # two evaluations gained < 1 point
    assert not flattened([0.1, 0.3, 0.5, 0.6], budget)      # still climbing
    assert not flattened([0.1, 0.5], budget)                # too few evaluations to tell
    # A fit that runs out of steps while climbing is flagged; one that flattened is not.
    net = LearnedReader.build(PLATE_FORMAT, 0)
    held = {32: simulate_plates(None, 2, (32, 32), np.random.default_rng(0), torch.Generator().manual_seed(0), 0.0,
                                PLATE_FORMAT, jitter=False)}
    curve = train_reader(net, [None], dataclasses.replace(budget, max_steps=2, patience=3), 0.0, 0, PLATE_FORMAT, 0, held)
    assert curve.stopped == "budget" and curve.still_rising and curve.steps == [1, 2]
    assert FitCurve.from_dict(curve.to_dict()) == curve


@pytest.fixture(scope="module")
def shipped_net():
    shipped = find_shipped("learned-reader", pretrained_key(PLATE_FORMAT))
    assert shipped is not None, "the package ships learned-reader's pre-trained weights (pretrain-attacker learned-reader)"
    reader = LearnedReader()
    net = reader.build(PLATE_FORMAT, 0)
    from attacks.readers.learned_reader import unpack_weights
    curve = unpack_weights(net, shipped.data)
    return net.eval(), curve, shipped


def test_shipped_start_reads_clean_plates_at_32_px(shipped_net):
    # Clean rendered plates (no lens, no noise) of 32 px +- 5 %, the true box: what read() makes of them.
    net, _, _ = shipped_net
    reader = LearnedReader()
    reader.net = net
    plates = simulate_plates(None, 200, (32, 32), np.random.default_rng(2026), torch.Generator().manual_seed(2026), 0.0,
                             PLATE_FORMAT, jitter=False)
    reads = reader.read(plates.images, attacks.ReadHints(plate_boxes=[[box] for box in plates.boxes]))
    correct = sum(r[0].text == text for r, text in zip(reads, plates.texts))
    assert correct / len(plates.texts) >= 0.95


def test_shipped_start_matches_its_recorded_curve(shipped_net):
    # The held-out set is a function of the seed: the shipped weights score now what their provenance says.
    from attacks.readers.learned_reader import PRETRAIN_BUDGET
    from attacks.training.plate_reader_training import held_out_set
    net, curve, shipped = shipped_net
    assert curve is not None and shipped.provenance["made"]["curve"]["accuracy"] == curve.accuracy
    held = held_out_set(None, PRETRAIN_BUDGET, 0.0, 0, PLATE_FORMAT, 0)
    for width, batch in held.items():
        assert plate_accuracy(net, batch) == pytest.approx(curve.per_width[curve.kept][width], abs=1.5 / len(batch.texts))


def test_fit_is_deterministic_per_seed_cached_and_reads_given_boxes():
    # No profile: the tiny budget (BUDGETS[None]), from the shipped start.
    lens = lenses.load("ideal")
    store = MemoryStore()
    fits = []
    for seed in (0, 0, 1):
        reader = LearnedReader(fit_seed=None)  # one fit per run seed
        reader.fit(attacks.FitContext(lens=lens, device="cpu", seed=seed, artifacts=None))
        fits.append(reader)
    state = [r.net.state_dict() for r in fits]
    assert all(torch.equal(state[0][k], state[1][k]) for k in state[0])
    assert not all(torch.equal(state[0][k], state[2][k]) for k in state[0])
    # The default: the fit depends on the lens alone, so every run seed of a fixed lens finds seed 0's fit.
    shared = MemoryStore()
    first_seed = attacks.load("learned-reader")
    first_seed.fit(attacks.FitContext(lens=lens, device="cpu", seed=0, artifacts=shared))
    other_seed = attacks.load("learned-reader")
    other_seed.fit(attacks.FitContext(lens=lens, device="cpu", seed=2, artifacts=shared))
    assert first_seed.trained and other_seed.trained is False and first_seed.fit_key == other_seed.fit_key
    assert all(torch.equal(a, b) for a, b in zip(first_seed.net.state_dict().values(), state[0].values()))
    first = attacks.load("learned-reader")
    first.fit(attacks.FitContext(lens=lens, device="cpu", seed=0, artifacts=store))
    again = attacks.load("learned-reader")
    report = again.fit(attacks.FitContext(lens=lens, device="cpu", seed=0, artifacts=store))
    assert first.trained and again.trained is False and again.curve == first.curve
    # A fit loaded from the cache reports the curve it was made with, and that it loaded.
    assert report.curve is not None and list(report.curve.steps) == first.curve.steps
    assert isinstance(report.still_rising, bool) and set(report.stage_seconds) == {"start", "load"}
    images = torch.rand(2, 3, 64, 128, generator=torch.Generator().manual_seed(3))
    boxes = [[(10.0, 10.0, 74.0, 24.0), (0.0, 0.0, 5.0, 2.0)], []]  # the 5 px box is below min_width_px
    reads = again.read(images, attacks.ReadHints(plate_boxes=boxes))
    assert [len(r) for r in reads] == [1, 0]
    assert reads[0][0].box_xyxy == boxes[0][0] and len(reads[0][0].text) == len(PLATE_FORMAT)
    assert 0.0 <= reads[0][0].score <= 1.0
    assert again.read(images, None) == [[], []]


def test_a_lens_that_forms_no_image_is_a_skip_not_a_crash(fake_lens):
    reader = attacks.load("learned-reader")
    reason = reader.skip_reason(attacks.FitContext(lens=fake_lens))
    assert reason and "lens(x, generator=g)" in reason


def test_with_no_lens_it_reads_with_its_sharp_start(shipped_net):
    # The sharp scenes (lens None): no fine-tuning, the shipped start itself reads, with no PSF margin.
    net, _, _ = shipped_net
    reader = attacks.load("learned-reader")
    assert reader.skip_reason(attacks.FitContext(lens=None)) is None
    report = reader.fit(attacks.FitContext(lens=None, device="cpu", seed=0, artifacts=MemoryStore()))
    assert reader.trained is False and reader.spread_px == 0.0 and reader.curve is None
    assert all(torch.equal(a, b) for a, b in zip(reader.net.state_dict().values(), net.state_dict().values()))
    assert report.curve is None and report.still_rising is None


@pytest.mark.slow
@pytest.mark.skipif(not __import__("os").environ.get("RUN_SLOW"), reason="fine-tunes on the quick ideal lens (minutes): RUN_SLOW=1")
def test_on_the_ideal_lens_it_reads_more_quick_plates_than_lpdr_oracle_and_never_above_the_ceiling():
    from benchmark.studies.reader_study import run_reader_study
    record = run_reader_study(("ideal",), ("learned-reader", "lpdr-oracle"), n_plates=200, out_json=None)
    plates = record["plates"]
    read = {r: sum(p["correct"] for p in plates if p["attack"] == r) for r in ("learned-reader", "lpdr-oracle")}
    assert read["learned-reader"] > read["lpdr-oracle"], read
    # Bins with enough plates to tell are checked against the lens's T = 1 ceiling by the study itself.
    assert record["consistency"]["violations"] == []


def test_a_fit_keeps_the_weights_of_its_best_held_out_evaluation(monkeypatch):
    # Held-out scores scripted per evaluation (0.5, 0.9, 0.2, 0.1): the fit ends on the weights it had at
    # the second, and says so; the curve itself is what was measured.
    import attacks.training.plate_reader_training as training
    from attacks.training.plate_reader_training import ReaderBudget, held_out_set, train_reader

    budget = ReaderBudget(max_steps=4, batch_size=4, lr=1e-2, widths_px=(24.0, 64.0), eval_every=1, eval_plates=2,
                          patience=10)
    held = held_out_set(None, budget, 0.0, 0, PLATE_FORMAT, 0)
    scripted, snapshots, calls = [0.5, 0.9, 0.2, 0.1], [], []

    def scored(net, batch):
        if len(calls) % len(held) == 0:
            snapshots.append({k: v.clone() for k, v in net.state_dict().items()})
        calls.append(1)
        return scripted[(len(calls) - 1) // len(held)]
    monkeypatch.setattr(training, "plate_accuracy", scored)
    net = LearnedReader.build(PLATE_FORMAT, 0)
    curve = train_reader(net, [None], budget, 0.0, 0, PLATE_FORMAT, 0, held)
    assert curve.accuracy == pytest.approx(scripted) and curve.best_step == 2 and curve.kept == 1
    state = net.state_dict()
    assert all(torch.equal(state[k], snapshots[1][k]) for k in state)
    assert not all(torch.equal(state[k], snapshots[3][k]) for k in state)
    # A curve stored before the rule has no best_step: it kept its last evaluation's weights.
    old = {k: v for k, v in curve.to_dict().items() if k != "best_step"}
    assert training.FitCurve.from_dict(old).best_step == 4 and training.FitCurve.from_dict(old).kept == 3


@pytest.mark.parametrize("min_steps, stops_at", [(0, 3), (5, 5)])
def test_a_fit_never_stops_as_flattened_before_its_min_steps(monkeypatch, min_steps, stops_at):
    # A flat scripted curve flattens after patience (2) evaluations; with min_steps 5 it goes on to step 5.
    import attacks.training.plate_reader_training as training
    from attacks.training.plate_reader_training import ReaderBudget, held_out_set, train_reader

    budget = ReaderBudget(max_steps=6, batch_size=4, lr=1e-2, widths_px=(24.0, 64.0), eval_every=1, eval_plates=2,
                          patience=2, min_steps=min_steps)
    held = held_out_set(None, budget, 0.0, 0, PLATE_FORMAT, 0)
    monkeypatch.setattr(training, "plate_accuracy", lambda net, batch: 0.3)
    curve = train_reader(LearnedReader.build(PLATE_FORMAT, 0), [None], budget, 0.0, 0, PLATE_FORMAT, 0, held)
    assert curve.steps[-1] == stops_at and curve.stopped == "flattened" and not curve.still_rising


def test_cached_weights_that_do_not_fit_are_refitted_from_a_clean_start():
    # A cached artifact whose tensors all load but one (wrong shape): the fit starts again from the shipped
    # start, not from the weights the failed load already copied, so it equals a fit from an empty cache.
    from safetensors.torch import save as save_safetensors
    lens = lenses.load("ideal")
    store = MemoryStore()
    first = attacks.load("learned-reader")
    first.fit(attacks.FitContext(lens=lens, device="cpu", seed=0, artifacts=store))
    (name,) = store.items
    state = {k: torch.full_like(v, 0.5) for k, v in first.net.state_dict().items()}
    last = sorted(state)[-1]
    state[last] = torch.zeros(3, 1)
    store.items[name] = save_safetensors(state)
    again = attacks.load("learned-reader")
    again.fit(attacks.FitContext(lens=lens, device="cpu", seed=0, artifacts=store))
    assert again.trained and again.shipped_fit is None
    assert all(torch.equal(a, b) for a, b in zip(again.net.state_dict().values(), first.net.state_dict().values()))


def test_the_row_notes_say_where_the_fit_stopped_and_which_step_it_kept():
    from benchmark.runner.evaluation import fit_notes
    reader = attacks.load("learned-reader")
    report = reader.fit(attacks.FitContext(lens=lenses.load("ideal"), device="cpu", seed=0,
                                           artifacts=MemoryStore()))
    curve = reader.curve
    notes = fit_notes(report)
    assert notes["fit_stopped"] == f"{curve.stopped} at step {curve.steps[-1]}, kept step {curve.best_step}"
    assert notes["fit_still_rising"] == ("true" if curve.still_rising else "false")
    assert report.stage_seconds["fine-tune"] > 0
    # A report without a curve or a verdict gives no notes; nor does anything that is not a report.
    assert fit_notes(attacks.FitReport()) == {} and fit_notes(None) == {}
    assert fit_notes({"fit_curve": {"steps": [1], "stopped": "budget"}, "fit_still_rising": True}) == {}


@pytest.mark.parametrize("garbage", [b"\xff" * 64, b"\x08\x00\x00\x00\x00\x00\x00\x00{\"a\":1}"])
def test_a_cached_artifact_that_is_not_safetensors_is_refitted_and_overwritten(garbage, caplog):
    # Bytes that pass the cache's checksum (it verifies what was written) but are no safetensors file: the
    # fit names the artifact, fits again and overwrites it, so the next run loads a good one.
    lens = lenses.load("ideal")
    store = MemoryStore()
    first = attacks.load("learned-reader")
    first.fit(attacks.FitContext(lens=lens, device="cpu", seed=0, artifacts=store))
    (name,) = store.items
    store.items[name] = garbage
    again = attacks.load("learned-reader")
    with caplog.at_level("WARNING"):
        again.fit(attacks.FitContext(lens=lens, device="cpu", seed=0, artifacts=store))
    assert again.trained and store.items[name] != garbage
    assert "learned-reader: the cached weights of key" in caplog.text and "do not load" in caplog.text
    # The stored fit is the refit (the same weights as the first fit: a fit is deterministic) and loads.
    third = attacks.load("learned-reader")
    third.fit(attacks.FitContext(lens=lens, device="cpu", seed=0, artifacts=store))
    assert third.trained is False
    assert all(torch.equal(a, b) for a, b in zip(third.net.state_dict().values(), first.net.state_dict().values()))
