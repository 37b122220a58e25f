"""The standard-ensemble choice: removal effects are exact, and the proposed
ensemble constant and docs/ensemble.md are what the rule selects on the published quick entries."""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest

from benchmark.results.ensemble import plate_ensemble, scene_ensemble
from benchmark.results.ensemble_choice import (
    PLATE_POINTS, Outcomes, complete_ensemble, keeps, proposed_ensemble, removal_effects, strongest_restorer)
from benchmark.results.entries import LEADERBOARD, Entry
from benchmark.results.schema import Row, Units
from benchmark.runner.defaults import PROPOSED_ENSEMBLE
from benchmark.studies import ensemble_choice_study as study


def _reader(attack: str, seed: int, correct: list[int]) -> Row:
    names = [f"p{i}" for i in range(len(correct))]
    restorer, _, reader = attack.rpartition(">")
    return Row(kind="chain" if restorer else "reader", attack=attack, restorer=restorer or None, reader=reader,
               lens="L", profile="quick", scenes="synthetic", seed=seed,
               metrics={"plate_acc": float(np.mean(correct))},
               units=Units("plate", "", tuple(names), {"correct": tuple(int(c) for c in correct)}))


def _restorer(attack: str, seed: int, psnr: list[float]) -> Row:
    return Row(kind="restorer", attack=attack, restorer=attack, lens="L", profile="quick", scenes="synthetic", seed=seed,
               metrics={"psnr_db": float(np.mean(psnr))},
               units=Units("scene", "", tuple(f"s{i}" for i in range(len(psnr))), {"psnr_db": tuple(psnr)}))


def _entry(rows: list[Row]) -> Entry:
    return Entry(lens="L", profile="quick", scenes="synthetic", seeds=sorted({r.seed for r in rows}),
                 profile_values={}, coefficients_um=None, lens_spec=None, settings={}, rows=rows)


@pytest.fixture
def toy() -> Entry:
    # 10 plates: `a` reads 0-3, `w>a` reads 3-5, `x>a` reads 5; restorers: `r` best on 2 scenes by 1 dB, `s` on one.
    return _entry([_reader("a", 0, [1, 1, 1, 1, 0, 0, 0, 0, 0, 0]),
                   _reader("w>a", 0, [0, 0, 0, 1, 1, 1, 0, 0, 0, 0]),
                   _reader("x>a", 0, [0, 0, 0, 0, 0, 1, 0, 0, 0, 0]),
                   _restorer("r", 0, [21.0, 22.0, 20.0, 20.0]),
                   _restorer("s", 0, [20.0, 21.0, 20.5, 20.0])])


def test_first_only_and_removal_effects_count_the_plates_and_scenes(toy):
    effects = {e.attack: e for e in removal_effects([toy])}
    assert (effects["a"].first, effects["a"].only) == (4, 3)
    assert (effects["w>a"].first, effects["w>a"].only) == (2, 1)  # plate 3 is a's first; 5 is shared with x>a
    assert (effects["x>a"].first, effects["x>a"].only) == (0, 0)
    assert effects["a"].plate_points == pytest.approx(30.0)
    assert effects["w>a"].plate_points == pytest.approx(10.0)
    assert effects["x>a"].plate_points == 0.0 and not effects["x>a"].decides and not effects["x>a"].matters
    # r is best on scenes 0 and 1 by 1 dB each (4 scenes): removing it costs 0.5 dB; s is best on scene 2 by 0.5.
    assert (effects["r"].best_scenes, effects["s"].best_scenes) == (3, 1)  # scene 3 ties: the first named
    assert effects["r"].psnr_db == pytest.approx(0.5) and effects["s"].psnr_db == pytest.approx(0.125)
    assert keeps(effects.values()) == ["a", "w>a", "r", "s"]
    assert strongest_restorer(effects.values()) == "r"
    assert proposed_ensemble(list(effects.values())) == ("a", "lpdr", "r", "r>lpdr", "s", "w>a")


def test_thresholds_are_strict():
    # One plate in 100 is exactly 1 point: not more than 1, so the rule drops the chain.
    rows = [_reader("a", 0, [1] * 10 + [0] * 90), _reader("b", 0, [0] * 10 + [1] + [0] * 89)]
    effects = {e.attack: e for e in removal_effects([_entry(rows)])}
    assert effects["b"].plate_points == pytest.approx(1.0) and not effects["b"].matters
    rows += [_reader("a", 1, [0] * 100), _reader("b", 1, [0] * 98 + [1, 1])]  # pooled: 3 of 200 plates
    effects = {e.attack: e for e in removal_effects([_entry(rows)])}
    assert effects["b"].plate_points == pytest.approx(1.5) and effects["b"].matters


@pytest.mark.slow
def test_removal_effects_agree_with_the_ensembles_themselves():
    entries = study.quick_entries(LEADERBOARD)
    entry = next(e for _, e in entries if e.lens == "os")
    plates, scenes = plate_ensemble(entry.rows), scene_ensemble(entry.rows, n_resamples=10)
    for effect in removal_effects([entry]):
        if effect.kind == "plates":
            without = plate_ensemble(entry.rows, set(plates.chains) - {effect.attack})
            assert effect.plate_points == pytest.approx(100 * (plates.accuracy.value - without.accuracy.value))
            assert effect.only == next(c.only for c in plates.contributions if c.attack == effect.attack)
        else:
            without = scene_ensemble(entry.rows, attacks=set(scenes.restorers) - {effect.attack}, n_resamples=10)
            assert effect.psnr_db == pytest.approx(scenes.mean - without.mean)
            assert effect.best_scenes == scenes.best_counts[scenes.restorers.index(effect.attack)]


@pytest.mark.slow
def test_the_proposed_constant_is_what_the_rule_selects_on_the_published_entries():
    entries = [e for _, e in study.quick_entries(LEADERBOARD)]
    assert entries and all(e.profile == "quick" for e in entries)
    effects = removal_effects(entries)
    assert PROPOSED_ENSEMBLE == proposed_ensemble(effects), "re-run python -m benchmark.studies.ensemble_choice_study"
    # Every chain it keeps by the rule passes it on some lens; every chain it leaves out passes it on none.
    for attack in {e.attack for e in effects}:
        passes = any(e.matters for e in effects if e.attack == attack)
        assert passes == (attack in keeps(effects))
    assert "lpdr" in PROPOSED_ENSEMBLE and f"{strongest_restorer(effects)}>lpdr" in PROPOSED_ENSEMBLE


@pytest.mark.slow
def test_the_docs_page_is_rendered_from_the_published_entries():
    text = study.DOC.read_text()
    date = study.date_of(text)
    assert date, "docs/ensemble.md states no date"
    assert text == study.render(LEADERBOARD, date), "docs/ensemble.md is stale: python -m benchmark.studies.ensemble_choice_study"


def test_a_chain_that_reads_a_plate_no_other_reads_starts_to_decide(toy):
    # `x>a` now reads plate 9 (read by no other chain) instead of the shared plate 5.
    rows = [dataclasses.replace(r, units=dataclasses.replace(r.units, values={"correct": (0,) * 9 + (1,)}))
            if r.attack == "x>a" else r for r in toy.rows]
    effects = {e.attack: e for e in removal_effects([_entry(rows)])}
    assert (effects["x>a"].first, effects["x>a"].only) == (1, 1)
    assert effects["x>a"].plate_points == pytest.approx(10.0) and effects["x>a"].matters
    assert effects["w>a"].only == 2  # plate 5 is its own now


def _timed(row: Row, seconds: float, fit_s: float = 0.0) -> Row:
    return dataclasses.replace(row, metrics={**row.metrics, "n_images": 10.0, "images_per_s": 10.0 / seconds,
                                             "fit_s": fit_s})


def test_chains_that_read_plates_only_together_are_completed_cheapest_first():
    # 100 plates. `a` reads 0-59; `r>b` and `q>b` both read 60-62 (each alone is redundant: removal effect 0,
    # together 3 points); `r>b` needs restorer `r` (fit 100 s), `q>b` restorer `q` (fit 1 s): the cheap one is added.
    # `z` reads 63 alone (1 point, within the threshold, at 10 s): not needed once `q>b` is in.
    def reads(idx):
        return [int(i in idx) for i in range(100)]
    rows = [_timed(_reader("a", 0, reads(range(60))), 5.0),
            _timed(_reader("r>b", 0, reads(range(60, 63))), 5.0), _timed(_reader("q>b", 0, reads(range(60, 63))), 5.0),
            _timed(_reader("z", 0, reads([63])), 10.0),
            _timed(_restorer("r", 0, [20.0, 20.0]), 2.0, fit_s=100.0), _timed(_restorer("q", 0, [20.0, 20.0]), 2.0, 1.0),
            _timed(_restorer("s", 0, [21.0, 21.0]), 2.0)]
    effects = {e.attack: e for e in removal_effects([_entry(rows)])}
    assert not effects["r>b"].matters and not effects["q>b"].matters  # the single-removal rule keeps neither
    outcomes = [Outcomes.of(rows, "L", 0)]
    assert outcomes[0].loss({"a", "s"}) == pytest.approx((4.0, 0.0)) and outcomes[0].loss({"a"})[1] == 21.0
    chains, added = complete_ensemble(["a", "s"], outcomes)
    assert added == ("q>b",) and set(chains) == {"a", "s", "q>b", "q"}
    assert outcomes[0].loss(set(chains))[0] == pytest.approx(1.0) and PLATE_POINTS == 1.0
    # A start that already reads everything needs nothing; a chain after a restorer brings the restorer.
    assert complete_ensemble(["a", "r>b", "z", "s"], outcomes) == (("a", "r", "r>b", "s", "z"), ())
