"""The per-unit worst case over every attacker (benchmark.results.ensemble), the attack gap and its flags
(benchmark.results.attack_gap), and findings decided on the ensemble (benchmark.publish.findings), on
constructed rows whose right answers are known."""

import dataclasses
import json
import math
from pathlib import Path

import numpy as np
import pytest

from benchmark.publish import findings
from benchmark.results import stats
from benchmark.results.attack_gap import attack_gaps, lens_flags, pooled_bracket
from benchmark.results.ensemble import (chain_accuracy, plate_ensemble, pooled_min_width, scene_ensemble,
                                       strongest_chain)
from benchmark.results.plate_scoring import LEGACY_READABLE_MIN_WIDTH_PX, READABLE_MIN_WIDTH_PX
from benchmark.results.entries import make_entry
from benchmark.results.observer.ceiling import CeilingCurve
from benchmark.results.schema import FIT_STILL_RISING, LEARNS, Row, Units

PROFILE = "quick"
ROOT = Path(__file__).resolve().parents[3]


def _plates(seed: int, n: int) -> list[str]:
    return [f"synthetic/val/{seed}/{i:05d}@x0y0p0#0" for i in range(n)]


def _reader(attack: str, seed: int, correct, lens: str = "gp", kind: str = "reader", threat: str = "sensor-access",
            widths=None, order=None) -> Row:
    correct = np.asarray(correct, dtype=int)
    names = _plates(seed, len(correct))
    values = {"correct": correct.tolist(), "char_errors": (7 * (1 - correct)).tolist()}
    if widths is not None:
        values["width_px"] = list(widths)
    if order is not None:  # the same plates listed in another order
        names = [names[i] for i in order]
        values = {k: [v[i] for i in order] for k, v in values.items()}
    restorer, reader = (attack.split(">") if ">" in attack else (None, attack))
    if kind == "reference":
        restorer, reader = None, None
    row = Row(kind=kind, lens=lens, attack=attack, restorer=restorer, reader=reader, seed=seed, profile=PROFILE,
              scenes="synthetic", threat_model=threat,
              metrics={"plate_acc": float(correct.mean()), "n_plates": float(len(correct))})
    row.set_units(Units.from_names("plate", names, values))
    return row


def _restorer(attack: str, seed: int, psnr, lens: str = "gp", threat: str = "sensor-access") -> Row:
    psnr = np.asarray(psnr, dtype=float)
    row = Row(kind="restorer", lens=lens, attack=attack, restorer=attack, seed=seed, profile=PROFILE,
              scenes="synthetic", threat_model=threat, metrics={"psnr_db": float(psnr.mean())})
    row.set_units(Units.from_names("scene", [f"synthetic/val/{seed}/{i:05d}" for i in range(len(psnr))],
                                   {"psnr_db": psnr.tolist()}))
    return row


def test_union_of_two_readers_each_reading_half_gives_accuracy_and_contributions():
    # 8 plates: A reads 0-3, B reads 2-5 (B's units listed backwards: pairing is by name). The ensemble
    # reads 0-5 = 6 of 8; each chain read 4 of those 6, and 2 that no other chain read.
    a = _reader("lpdr-oracle", 0, [1, 1, 1, 1, 0, 0, 0, 0])
    b = _reader("wiener-known-psf>lpdr-oracle", 0, [0, 0, 1, 1, 1, 1, 0, 0], kind="chain",
                order=[7, 6, 5, 4, 3, 2, 1, 0])
    raw = _reader("raw>lpdr-oracle", 0, [0, 0, 0, 0, 0, 0, 1, 1], kind="reference")  # not an attacker
    ensemble = plate_ensemble([a, b, raw])
    assert ensemble is not None and ensemble.chains == ("lpdr-oracle", "wiener-known-psf>lpdr-oracle")
    assert (ensemble.accuracy.hits, ensemble.accuracy.n) == (6, 8)
    assert ensemble.accuracy.interval == stats.wilson_interval(6, 8)
    assert ensemble.bins is None and ensemble.min_width_px() == 32  # no widths recorded: every readable plate
    for c in ensemble.contributions:
        assert (c.read, c.only, c.of) == (4, 2, 6)
        assert c.share == pytest.approx(4 / 6) and c.only_share == pytest.approx(2 / 6)
    single = strongest_chain(ensemble)
    assert single is not None and single[0] == "lpdr-oracle" and single[1].value == 0.5


def test_union_pools_seeds_and_a_chain_missing_a_seed():
    seed0 = [_reader("lpdr", 0, [1, 0, 0, 0]), _reader("lpdr-oracle", 0, [0, 1, 0, 0])]
    seed1 = [_reader("lpdr-oracle", 1, [1, 1, 1, 0])]  # lpdr ran at seed 0 only
    ensemble = plate_ensemble(seed0 + seed1)
    assert ensemble is not None and ensemble.seeds == (0, 1)
    assert (ensemble.accuracy.hits, ensemble.accuracy.n) == (5, 8)
    assert ensemble.accuracy.seed_values == (0.5, 0.75)
    assert ensemble.accuracy.seed_std == pytest.approx(np.std([0.5, 0.75], ddof=1))
    lpdr = next(c for c in ensemble.contributions if c.attack == "lpdr")
    assert (lpdr.seeds, lpdr.read, lpdr.only, lpdr.of) == ((0,), 1, 1, 5)
    assert chain_accuracy(ensemble, "lpdr").value == 0.25  # on its own seed's plates only
    # A threat-model view keeps only the chains asked for.
    only = plate_ensemble(seed0 + seed1, attacks={"lpdr"})
    assert only is not None and (only.accuracy.hits, only.accuracy.n) == (1, 4)


def test_width_bins_where_plates_record_widths():
    widths = [16, 20, 32, 40, 64, 70]
    a = _reader("lpdr-oracle", 0, [0, 0, 1, 0, 1, 1], widths=widths)
    b = _reader("identity>lpdr-oracle", 0, [1, 0, 0, 1, 0, 0], kind="chain", widths=widths)
    ensemble = plate_ensemble([a, b], bins_px=(16, 32, 64))
    assert ensemble is not None and ensemble.bins is not None
    got = {(b.low_px, b.high_px): (b.accuracy.hits, b.accuracy.n) for b in ensemble.bins}
    assert got == {(16.0, 32.0): (1, 2), (32.0, 64.0): (2, 2), (64.0, math.inf): (2, 2)}
    # The pooled accuracy and the chains' shares count only the readable plates (>= the measured start).
    readable = [w >= READABLE_MIN_WIDTH_PX for w in widths]
    union = [x or y for x, y in zip([0, 0, 1, 0, 1, 1], [1, 0, 0, 1, 0, 0])]
    assert (ensemble.accuracy.hits, ensemble.accuracy.n) == (sum(u for u, r in zip(union, readable) if r),
                                                             sum(readable))
    assert ensemble.min_width_px() == READABLE_MIN_WIDTH_PX
    assert pooled_min_width([a, b]) == READABLE_MIN_WIDTH_PX
    # Plates recorded only from 32 px (runs before plates were scored from 8 px) pool from 32 px.
    wide = [_reader("lpdr-oracle", 0, [0, 1], widths=[32, 40])]
    assert plate_ensemble(wide).min_width_px() == pooled_min_width(wide) == LEGACY_READABLE_MIN_WIDTH_PX
    b_bad = _reader("identity>lpdr-oracle", 0, [1, 0, 0, 1, 0, 0], kind="chain", widths=[16, 20, 32, 40, 64, 99])
    with pytest.raises(ValueError, match="identity>lpdr-oracle.*width_px"):
        plate_ensemble([a, b_bad])


def test_each_scene_counts_at_its_best_restorer():
    rows = [_restorer("wiener-known-psf", 0, [10.0, 20.0, 30.0, 12.0]),
            _restorer("nafnet-known-pairs", 0, [25.0, 15.0, 35.0, 11.0], threat="known-pairs")]
    found = scene_ensemble(rows)
    assert found is not None
    assert found.mean == pytest.approx(np.mean([25.0, 20.0, 35.0, 12.0]))
    assert found.best_counts == (2, 2) and found.n_scenes == 4
    assert found.interval[0] <= found.mean <= found.interval[1]
    # Above the better single restorer's mean (21.5): picking per scene is the stronger attack.
    assert found.mean > max(np.mean([10, 20, 30, 12]), np.mean([25, 15, 35, 11]))
    two_seeds = rows + [_restorer("wiener-known-psf", 1, [14.0, 16.0])]
    pooled = scene_ensemble(two_seeds)
    assert pooled is not None and pooled.seed_values == (pytest.approx(23.0), pytest.approx(15.0))
    assert pooled.mean == pytest.approx(19.0) and pooled.interval[0] <= 19.0 <= pooled.interval[1]


# ---- the gap and the flags ------------------------------------------------------------------------

def _curve(widths=(16, 32, 64), ceiling=(0.6, 0.9, 1.0), half=0.02) -> CeilingCurve:
    n = len(widths)
    plate = np.array(ceiling, dtype=float)
    interval = np.stack([np.clip(plate - half, 0, 1), np.clip(plate + half, 0, 1)], axis=1)
    return CeilingCurve(lens="defocus", frames=1, widths_px=np.array(widths), char_ceiling=plate,
                        char_interval=interval, position_ceiling=np.tile(plate[:, None], (1, 7)),
                        position_interval=np.tile(interval[:, None, :], (1, 7, 1)), plate_ceiling=plate,
                        plate_interval=interval, n_plates=np.full(n, 40), converged=np.ones(n, dtype=bool),
                        noise_draws=4, interval_width=0.01, seconds=0.0)


def _study(curve: CeilingCurve) -> tuple[dict, dict]:
    spec = json.loads((ROOT / "leaderboard/entries/defocus__quick__synthetic.json").read_text())["lens_spec"]
    return {"lenses": {"defocus": {"lens_spec": spec, "t1": {"curve": curve.to_dict()}}}}, spec


def _hits(k: int, n: int = 200) -> list[int]:
    return [1] * k + [0] * (n - k)


def test_gap_is_ceiling_at_the_bins_lower_edge_minus_the_ensemble():
    ensemble = plate_ensemble([_reader("lpdr-oracle", 0, _hits(50), lens="defocus")])
    (gap,) = attack_gaps(ensemble, _curve())
    assert gap.pooled and gap.low_px == 32 and gap.ceiling == pytest.approx(0.9)
    assert gap.gap == pytest.approx(0.9 - 0.25)
    low, high = stats.wilson_interval(50, 200)
    assert gap.interval == pytest.approx((0.88 - high, 0.92 - low))
    widths = [16] * 100 + [64] * 100
    binned = plate_ensemble([_reader("lpdr-oracle", 0, [1] * 10 + [0] * 90 + [1] * 100, lens="defocus",
                                     widths=widths)], bins_px=(16, 32, 64))
    by_low = {g.low_px: g for g in attack_gaps(binned, _curve())}
    assert set(by_low) == {16, 64} and not by_low[16].pooled
    assert by_low[16].gap == pytest.approx(0.6 - 0.1) and by_low[64].gap == pytest.approx(0.0)


def test_every_flag_trips_on_a_planted_case():
    study, spec = _study(_curve(ceiling=(0.6, 0.9, 0.9)))  # no plate from 32 px readable above 92 %
    rows = [
        _reader("lpdr-oracle", 0, _hits(20), lens="defocus"),                                   # 10 %: gap 80 pt
        _reader("wiener-known-psf>lpdr-oracle", 0, _hits(200), lens="defocus", kind="chain"),   # 100 %: above 92 %
        _restorer("nafnet-generic", 0, np.linspace(20, 30, 32) + 2.0, lens="defocus"),
        _restorer("nafnet-known-pairs", 0, np.linspace(20, 30, 32), lens="defocus", threat="known-pairs"),
    ]
    rows[3].notes[FIT_STILL_RISING] = "true"
    kinds = [f.kind for f in lens_flags("defocus", PROFILE, rows, spec, study)]
    assert kinds == ["above-ceiling", "fit-still-rising", "untrained-beats-trained"]
    # The gap flag: a weak ensemble where the ceiling is high (nothing above the ceiling).
    flags = lens_flags("defocus", PROFILE, rows[:1], spec, study)
    assert [f.kind for f in flags] == ["attack-gap"]
    assert "privacy is overstated" in flags[0].message and "80.0" in flags[0].message


def test_flags_stay_quiet_on_a_clean_case():
    study, spec = _study(_curve(ceiling=(0.6, 0.9, 0.9)))
    rows = [
        _reader("lpdr-oracle", 0, _hits(170), lens="defocus"),   # 85 %, below 90 % and within 30 points
        _restorer("nafnet-generic", 0, np.linspace(20, 30, 32), lens="defocus"),
        _restorer("nafnet-known-pairs", 0, np.linspace(20, 30, 32) + 1.0, lens="defocus", threat="known-pairs"),
    ]
    rows[2].notes[FIT_STILL_RISING] = "false"
    assert lens_flags("defocus", PROFILE, rows, spec, study) == []
    # Without a study record for the lens's spec, no ceiling flag can be raised.
    other = json.loads(json.dumps(spec))
    other["optics"]["focus_distance_m"] = 3.0
    assert lens_flags("defocus", PROFILE, [_reader("lpdr-oracle", 0, _hits(5), lens="defocus")], other, study) == []


def test_rows_that_say_whether_they_learn_are_held_against_each_other_across_families():
    # A learning lens-access restorer below Wiener (same threat model, another family) is under-fitted; a
    # known-pairs learner below Richardson-Lucy (lens access: a stronger threat model) is not compared.
    scenes = np.linspace(20, 30, 32)
    rows = [_restorer("wiener-known-psf", 0, scenes + 1.0, lens="defocus", threat="lens-access"),
            _restorer("richardson-lucy-known-psf", 0, scenes + 3.0, lens="defocus", threat="lens-access"),
            _restorer("nafnet-known-psf", 0, scenes, lens="defocus", threat="lens-access"),
            _restorer("nafnet-known-pairs", 0, scenes + 2.0, lens="defocus", threat="known-pairs")]
    for row, learns in zip(rows, ("false", "false", "true", "true")):
        row.notes[LEARNS] = learns
    messages = [f.message for f in lens_flags("defocus", PROFILE, rows, None, None) if f.kind == "untrained-beats-trained"]
    assert len(messages) == 2 and all(m.endswith("nafnet-known-psf is under-fitted") for m in messages)
    assert {m.split(" ")[0] for m in messages} == {"wiener-known-psf", "richardson-lucy-known-psf"}
    # The learner fixed (above both): no flag. Without the notes, the older same-family rule sees none.
    rows[2] = _restorer("nafnet-known-psf", 0, scenes + 4.0, lens="defocus", threat="lens-access")
    rows[2].notes[LEARNS] = "true"
    assert not [f for f in lens_flags("defocus", PROFILE, rows, None, None) if f.kind == "untrained-beats-trained"]
    legacy = [_restorer("wiener-known-psf", 0, scenes + 1.0, lens="defocus", threat="lens-access"),
              _restorer("nafnet-known-psf", 0, scenes, lens="defocus", threat="lens-access")]
    assert not [f for f in lens_flags("defocus", PROFILE, legacy, None, None) if f.kind == "untrained-beats-trained"]


def test_a_malformed_fit_note_names_the_row():
    row = _restorer("nafnet-known-pairs", 2, [20.0, 21.0], lens="defocus", threat="known-pairs")
    row.notes[FIT_STILL_RISING] = "maybe"
    with pytest.raises(ValueError, match="defocus/nafnet-known-pairs seed 2.*fit_still_rising"):
        lens_flags("defocus", PROFILE, [row], None, None)


# ---- findings on the ensemble ---------------------------------------------------------------------

def test_plate_finding_is_decided_on_the_ensemble_not_the_best_single_reader():
    # 80 plates. gp: two chains reading disjoint quarters (20 + 20: ensemble 40); os: both chains read the
    # same 30. The best single reader says gp reads fewer (20 against 30); every attacker at once, gp
    # leaks more (40 against 30, McNemar on 10 discordant plates, all gp's).
    gp = [_reader("lpdr-oracle", 0, [1] * 20 + [0] * 60),
          _reader("identity>lpdr-oracle", 0, [0] * 20 + [1] * 20 + [0] * 40, kind="chain")]
    os = [_reader("lpdr-oracle", 0, [1] * 30 + [0] * 50, lens="os"),
          _reader("identity>lpdr-oracle", 0, [1] * 30 + [0] * 50, lens="os", kind="chain")]
    entries = [make_entry("gp", gp, {"name": PROFILE}, None, None), make_entry("os", os, {"name": PROFILE}, None, None)]
    found = next(f for f in findings.check_findings(entries) if f.lens_b == "os" and f.measure == "plate_acc")
    assert found.comparison is not None and found.comparison.n == 80
    assert found.comparison.difference == pytest.approx(10 / 80)
    assert found.comparison.p_value == pytest.approx(stats.mcnemar_exact(10, 0))
    assert found.label == stats.DOES_NOT_HOLD  # the claim "GP lowers ..." is refuted by the ensemble
    assert found.attack_a == "ensemble of 2 chains" and found.a is not None and found.a.mean == pytest.approx(0.5)
    assert found.figure_text("a").startswith("50.0")


def test_pooled_bracket_is_the_mean_ceiling_over_the_same_readable_plates():
    # Plates of 16 (not readable: out of the pooled figure and of its ceiling), 24, 32, 48, 64 and 128 px against
    # a curve tabulated at 16, 32, 64 px: 24 and 48 px interpolate, 128 px counts at the widest (64 px).
    study, spec = _study(_curve())
    widths = [16, 24, 32, 48, 64, 128]
    rows = [_reader("lpdr-oracle", 0, [1, 1, 0, 0, 1, 0], lens="defocus", widths=widths)]
    entry = make_entry("defocus", rows, {"name": PROFILE}, None, spec)
    bracket = pooled_bracket(entry, study)
    assert bracket is not None and bracket.ceiling_kind == "genie"
    ceilings = [0.75, 0.9, 0.95, 1.0, 1.0]
    assert bracket.ceiling == pytest.approx(np.mean(ceilings))
    # The limits interpolate the tabulated (clipped) limits: 48 px lies between 0.92 and 1.0.
    assert bracket.ceiling_interval == pytest.approx((np.mean([c - 0.02 for c in ceilings]),
                                                      np.mean([0.77, 0.92, 0.96, 1.0, 1.0])))
    assert (bracket.ensemble.hits, bracket.ensemble.n) == (2, 5)  # the table's pooled figure: 24 px and up
    # A plate narrower than every tabulated width has no ceiling: no bracket rather than a guessed one.
    narrow, _ = _study(_curve(widths=(32, 64), ceiling=(0.9, 1.0)))
    assert pooled_bracket(entry, narrow) is None
    # No study record for the lens's spec: none either.
    assert pooled_bracket(make_entry("defocus", rows, {"name": PROFILE}, None, {"other": 1}), study) is None


def test_a_width_the_tighter_curve_lacks_takes_the_genies_before_any_clamp():
    from benchmark.results.attack_gap import _ceiling_of_width
    from benchmark.results.observer.nuisance import NuisancePrior
    genie = _curve()  # 16, 32, 64 px: 0.6, 0.9, 1.0
    tighter = dataclasses.replace(_curve(widths=(16,), ceiling=(0.5,)), prior=NuisancePrior(),
                                  width_high_px=np.array([32.0]))  # one bin, [16, 32)
    assert _ceiling_of_width(20, tighter, genie)[::2] == (0.5, "marginal")
    assert _ceiling_of_width(48, tighter, genie)[::2] == (pytest.approx(0.95), "genie")  # the genie tabulates 48
    assert _ceiling_of_width(128, tighter, genie)[::2] == (1.0, "genie")  # beyond both: the genie's widest
    assert _ceiling_of_width(128, tighter, None)[::2] == (0.5, "marginal")  # the tighter curve alone: its last bin
    assert _ceiling_of_width(8, tighter, genie) is None
