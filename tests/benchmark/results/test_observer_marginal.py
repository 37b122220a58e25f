"""The marginalised (tighter) ideal-observer ceiling against the genie's, a quadrature and planted readers."""

from __future__ import annotations

import json
import math

import numpy as np
import pytest
import torch
from scipy.special import roots_legendre
from scipy.integrate import simpson

import lenses
from benchmark.results.entries import LEADERBOARD
from benchmark.results.observer import published
from benchmark.results.observer.ceiling import CeilingCurve, PlateModel, Precision, ceiling_curves
from benchmark.results.observer.marginal import convergence, marginal_ceiling_curves, mixture_accuracy
from benchmark.results.observer.nuisance import NuisancePrior, area_weights, draw_points
from benchmark.results.schema import Row

FEW = Precision(min_plates=2, batch=2, max_plates=2)


def test_a_prior_collapsed_to_the_genies_point_gives_the_genies_curve():
    """The same seed draws the same plates and noise: one point is the genie exactly, M copies of it
    the genie to rounding (the likelihood averaged over M equal terms)."""
    lens = lenses.load("defocus")
    (genie,) = ceiling_curves(lens, (8, 12), precision=FEW, pair=None, seed=3)
    for points, tol in ((1, 0.0), (4, 1e-9)):
        (point,) = marginal_ceiling_curves(lens, (8, 12), prior=NuisancePrior.known(PlateModel().exposure, points),
                                           precision=FEW, seed=3)
        np.testing.assert_allclose(point.position_ceiling, genie.position_ceiling, rtol=0, atol=tol)
        np.testing.assert_allclose(point.plate_interval, genie.plate_interval, rtol=0, atol=tol)
    assert 0.05 < genie.plate_ceiling[0] < 0.95  # a test between chance and certainty


def test_the_marginalised_ceiling_never_exceeds_the_genies():
    """Per bin [8, 12) and [12, 16): the tighter ceiling (M = 8 continuous points, an upper bound at any M)
    is below the genie's at the bin's upper end (the genie rises with width: its most over the bin, the
    value the run's check compares a bin with), within their Monte-Carlo intervals; the fresh-nuisance
    rule sits below the ceiling."""
    lens = lenses.load("defocus")
    (genie,) = ceiling_curves(lens, (12, 16), precision=FEW, pair=None, seed=0)
    (tight,) = marginal_ceiling_curves(lens, (8, 12), prior=NuisancePrior(points=8), precision=FEW, seed=0)
    assert (tight.plate_interval[:, 0] <= genie.plate_interval[:, 1]).all()
    assert (tight.rule_plate <= tight.plate_ceiling).all()
    # The exact marginal over the four RGGB parities (every point of a discrete prior) at a known width:
    # at most the genie's at that width (told the parity), same plates and noise.
    (at_width,) = ceiling_curves(lens, (8, 12), precision=FEW, pair=None, seed=0)
    parity = NuisancePrior("pixel-grid", "known", (PlateModel().exposure,) * 2, exhaustive=True)
    (exact,) = marginal_ceiling_curves(lens, (8, 12), prior=parity, precision=FEW, seed=0)
    assert (exact.position_interval[..., 0] <= at_width.position_interval[..., 1]).all()


def _shifted_bump(centre_px: np.ndarray, amplitude_e: float, base_e: float) -> np.ndarray:
    """Mean electrons (..., 2) of two pixels (centres 0 and 1) seeing a Gaussian bump (sd 0.6 px) at centre_px."""
    x = np.array([0.0, 1.0])
    return base_e + amplitude_e * np.exp(-((x - np.asarray(centre_px)[..., None]) ** 2) / (2 * 0.6**2))


def test_two_hypotheses_with_a_uniformly_unknown_one_pixel_shift_match_quadrature():
    """Two pixels; hypothesis 0 a bump at s, hypothesis 1 the same bump one pixel on (1 + s), s uniform
    over [0, 1) and unknown. Reference: 1/2 the integral of max_a p(y | a) over y, p(y | a) the mixture
    over s by 64-node Gauss-Legendre, y on a Simpson grid (scipy); the noise model N(mu, mu + read^2)
    per pixel as the sensor's."""
    read, base, amp = 1000.0, 1000.0, 1800.0
    sigma = math.sqrt(read**2 + base)
    nodes, weights = roots_legendre(64)
    s, ws = (nodes + 1) / 2, weights / 2
    mu = np.stack([_shifted_bump(s, amp, base), _shifted_bump(1 + s, amp, base)])  # (2, 64, 2)
    grid = np.linspace(base - 8 * sigma, base + amp + 8 * sigma, 401)
    y0, y1 = np.meshgrid(grid, grid, indexing="ij")
    mixture = np.zeros((2,) + y0.shape)  # p(y | a) on the grid
    for a in (0, 1):
        for (m0, m1), w in zip(mu[a], ws):
            v0, v1 = m0 + read**2, m1 + read**2
            mixture[a] += w * np.exp(-0.5 * ((y0 - m0) ** 2 / v0 + (y1 - m1) ** 2 / v1)) / (2 * np.pi * np.sqrt(v0 * v1))
    mixture = np.moveaxis(mixture, 0, -1)
    assert simpson(simpson(mixture[..., 0], x=grid), x=grid) == pytest.approx(1.0, abs=1e-6)
    reference = 0.5 * simpson(simpson(mixture.max(-1), x=grid), x=grid)

    rng = np.random.default_rng(0)
    points = (np.arange(256) + rng.random()) / 256  # a randomly shifted grid: each point marginally uniform
    means = torch.from_numpy(np.stack([_shifted_bump(points, amp, base), _shifted_bump(1 + points, amp, base)]))
    fresh_s = rng.random((2, 4000))
    fresh = torch.from_numpy(np.stack([_shifted_bump(fresh_s[0], amp, base), _shifted_bump(1 + fresh_s[1], amp, base)]))
    ceiling, rule = mixture_accuracy(means, fresh, read, 1, 20000, np.random.default_rng(1), np.random.default_rng(2))
    assert 0.6 < reference < 0.9
    assert ceiling == pytest.approx(reference, abs=0.006)
    assert rule == pytest.approx(reference, abs=0.02)  # 8000 fresh observations: sd 0.005
    # The genie (told s: M = 1 at the true shift) reads markedly more: the shift is what hides the bump.
    told, _ = mixture_accuracy(means[:, :1], None, read, 1, 20000, np.random.default_rng(1), np.random.default_rng(2))
    assert told > reference + 0.05


def test_area_weights_integrate_a_box_exactly():
    """Four source pixels tiling [0.5, 2.5), each 0.5 px long: output pixel 0 holds source 0, pixel 1
    sources 1 and 2, pixel 2 source 3, pixel 3 nothing (the length of each output pixel each covers)."""
    r = area_weights(4, 4, 0.5, 2.0)
    np.testing.assert_allclose(r, [[0.5, 0, 0, 0], [0, 0.5, 0.5, 0], [0, 0, 0, 0.5], [0, 0, 0, 0]], atol=1e-15)
    # A source pixel split by an output pixel's edge: its length is shared in proportion.
    np.testing.assert_allclose(area_weights(2, 1, 0.25, 1.0), [[0.75], [0.25]], atol=1e-15)


def test_nuisance_points_follow_the_prior():
    prior = NuisancePrior(points=64)
    pts = draw_points(prior, 16, 24, PlateModel().aspect, 64, np.random.default_rng(0))
    x = np.array([p.x_px for p in pts])
    w = np.array([p.width_px for p in pts])
    e = np.array([p.exposure for p in pts])
    assert 0 <= x.min() and x.max() < 2 and 16 <= w.min() and w.max() < 24 and 0.85 <= e.min() and e.max() < 1.05
    # A scrambled Sobol set of 64: each quarter of [0, 2) holds 16 points.
    assert np.histogram(x, bins=4, range=(0, 2))[0].tolist() == [16] * 4
    grid = draw_points(NuisancePrior("pixel-grid", "pixel-grid"), 16, 24, PlateModel().aspect, 64,
                       np.random.default_rng(0), PlateModel().height_px)
    assert {p.x_px for p in grid} == {0.0, 1.0} and all(p.width_px == int(p.width_px) for p in grid)
    with pytest.raises(ValueError, match="position"):
        NuisancePrior(position="sub-pixel")


def _toy_curve(ceiling: float, interval: tuple[float, float], marginal: bool) -> CeilingCurve:
    """A one-width curve (24 px, where pooled plate figures start; the marginal one standing for [24, 36))
    with the given plate ceiling."""
    one, pair = np.array([ceiling]), np.array([interval])
    return CeilingCurve(lens="defocus", frames=1, widths_px=np.array([24]), char_ceiling=one, char_interval=pair,
                        position_ceiling=np.full((1, 7), ceiling), position_interval=np.repeat(pair[:, None], 7, 1),
                        plate_ceiling=one, plate_interval=pair, n_plates=np.array([8]), converged=np.array([True]),
                        noise_draws=2, interval_width=0.01, seconds=0.0,
                        prior=NuisancePrior() if marginal else None,
                        width_high_px=np.array([36.0]) if marginal else None,
                        rule_plate=one if marginal else None, rule_interval=pair if marginal else None)


@pytest.fixture(scope="module")
def planted() -> dict:
    """The two-pixel shifted-bump test as a 'lens': its genie and marginalised ceilings, and the per-plate
    reads of a reader told the shift (the genie's rule), one not told it (the mixture rule) and a cheat."""
    read, base, amp = 1000.0, 1000.0, 1800.0
    rng = np.random.default_rng(5)
    points = (np.arange(256) + rng.random()) / 256
    means = torch.from_numpy(np.stack([_shifted_bump(points, amp, base), _shifted_bump(1 + points, amp, base)]))
    tight, _ = mixture_accuracy(means, None, read, 1, 5000, np.random.default_rng(1), np.random.default_rng(2))
    genie, _ = mixture_accuracy(means[:, :1], None, read, 1, 5000, np.random.default_rng(1), np.random.default_rng(2))
    n = 400
    truth, shift = rng.integers(2, size=n), rng.random(n)
    mu = _shifted_bump(truth + shift, amp, base)
    y = mu + np.sqrt(mu + read**2) * rng.standard_normal(mu.shape)

    def loglik(m: np.ndarray) -> np.ndarray:  # log N(y; m, m + read^2), summed over the pixels
        v = m + read**2
        return -0.5 * (((y[..., None, :] - m) ** 2) / v + np.log(v)).sum(-1)

    told = np.stack([loglik(_shifted_bump(a + shift, amp, base)[:, None, :])[:, 0] for a in (0, 1)], -1)
    mixed = np.stack([np.logaddexp.reduce(loglik(_shifted_bump(a + points, amp, base)[None]), -1) for a in (0, 1)], -1)
    reads = {"knows-shift": told.argmax(-1) == truth, "honest": mixed.argmax(-1) == truth, "cheat": np.ones(n, bool)}
    half = 1.96 * 0.5 / math.sqrt(5000)
    curves = {"genie": _toy_curve(genie, (genie - half, genie + half), False),
              "marginal": _toy_curve(tight, (tight - half, tight + half), True)}
    return {"reads": reads, "curves": curves}


def _study(curves: dict) -> tuple[dict, dict]:
    stored = json.loads((LEADERBOARD / "studies" / "ideal_observer.json").read_text())
    spec = stored["lenses"]["defocus"]["lens_spec"]
    record = {"lens_spec": spec, "t1": {"curve": curves["genie"].to_dict()},
              "marginal": {"t1": {"curve": curves["marginal"].to_dict()}}}
    return {"lenses": {"defocus": record}}, spec


def test_a_reader_told_the_nuisance_may_cross_the_tighter_ceiling_and_the_check_names_it(planted):
    """The reader told the shift reads above the marginalised ceiling (reported as such, its row kept);
    the honest mixture reader does not cross it; the cheat crosses the genie's (its row failed)."""
    reads, curves = planted["reads"], planted["curves"]
    assert curves["marginal"].plate_ceiling[0] + 0.05 < reads["knows-shift"].mean() <= curves["genie"].plate_ceiling[0] + 0.05
    study, spec = _study(curves)
    records = [{"lens": "defocus", "attack": attack, "width_px": 24 + i % 8, "correct": bool(hit)}
               for attack, hits in reads.items() for i, hit in enumerate(hits)]
    check = published.run_violations(records, {"defocus": {"spec": spec}}, study)
    assert [(v["reader"], v["ceiling"]) for v in check["violations"]] == [("cheat", "genie")]
    assert [(v["reader"], v["ceiling"]) for v in check["above_tighter"]] == [("knows-shift", "marginal")]
    assert check["above_tighter"][0]["message"].startswith("ABOVE THE TIGHTER CEILING")
    assert check["tighter_checked"] == ["defocus"] and "1 bin(s) above the tighter ceiling alone" in check["summary"]
    rows = [Row(kind="reader", attack=a, reader=a, threat_model="lens-access", lens="defocus", seed=0,
                profile="quick", scenes="synthetic", metrics={"plate_acc": float(h.mean()), "n_plates": 400.0})
            for a, h in reads.items()]
    failed = published.fail_above_ceiling(rows, check["violations"] + check["above_tighter"])
    assert [r.attack for r in failed if not r.ok] == ["cheat"]
    assert "genie" in failed[-1].error.message


def test_the_attack_gap_is_taken_against_the_tighter_ceiling_and_flags_name_both(planted):
    from benchmark.results.attack_gap import entry_gaps, lens_flags
    from benchmark.results.entries import make_entry
    from benchmark.results.schema import Units
    reads, curves = planted["reads"], planted["curves"]
    study, spec = _study(curves)
    rows = []
    for attack in ("knows-shift", "cheat"):
        row = Row(kind="reader", attack=attack, reader=attack, threat_model="lens-access", lens="defocus", seed=0,
                  profile="quick", scenes="synthetic", metrics={"plate_acc": float(reads[attack].mean()),
                                                                 "n_plates": 400.0})
        names = [f"synthetic/val/0/{i:05d}@x0y0p0#0" for i in range(400)]
        row.set_units(Units.from_names("plate", names, {"correct": reads[attack].astype(int).tolist(),
                                                        "char_errors": [0] * 400, "width_px": [30] * 400}))
        rows.append(row)
    entry = make_entry("defocus", rows[:1], {}, None, spec)
    (gap,) = entry_gaps(entry, study)
    assert gap.ceiling_kind == "marginal" and gap.ceiling == pytest.approx(curves["marginal"].plate_ceiling[0])
    kinds = [f.kind for f in lens_flags("defocus", "quick", rows, spec, study)]
    assert kinds == ["above-ceiling", "above-tighter-ceiling"]
    # Without the tighter curve the gap falls back to the genie's, saying so.
    genie_only = {"lenses": {"defocus": {k: v for k, v in study["lenses"]["defocus"].items() if k != "marginal"}}}
    (gap,) = entry_gaps(entry, genie_only)
    assert gap.ceiling_kind == "genie"


def test_curves_round_trip_through_json_and_old_records_have_no_tighter_ceiling():
    curve = _toy_curve(0.4, (0.35, 0.45), True)
    back = CeilingCurve.from_dict(json.loads(json.dumps(curve.to_dict())))
    assert back.prior == curve.prior and back.kind == "marginal" and back.width_high_px.tolist() == [36.0]
    stored = json.loads((LEADERBOARD / "studies" / "ideal_observer.json").read_text())
    record = stored["lenses"]["defocus"]
    assert published.t1_curve(record).kind == "genie"
    if "marginal" not in record:
        assert published.marginal_t1_curve(record) is None


@pytest.mark.slow
def test_the_pair_block_at_the_genies_point_agrees_with_the_genies_pair():
    """The first two letters read jointly (676 hypotheses, 64 sampled truths per plate) with the prior at the
    genie's point: the genie's pair ceiling within the two Monte-Carlo intervals (defocus, 8 px, near chance,
    where the pair certifies what no single letter can)."""
    lens = lenses.load("defocus")
    few = Precision(min_plates=3, batch=3, max_plates=3)
    (genie,) = ceiling_curves(lens, (8,), precision=few, seed=0)
    (point,) = marginal_ceiling_curves(lens, (8,), prior=NuisancePrior.known(PlateModel().exposure), precision=few,
                                       seed=0, pair=(0, 1))
    assert point.pair_ceiling[0] < 1 / 26 and point.plate_ceiling[0] == point.pair_ceiling[0]
    low, high = point.pair_interval[0]
    assert low - 0.01 <= genie.pair_ceiling[0] <= high + 0.01


@pytest.mark.slow
def test_convergence_tabulates_a_falling_ceiling_against_the_points():
    """On the ideal lens at [8, 12) px: the M-point ceiling at M = 16 is below M = 1's, and the
    fresh-nuisance rule stays below the ceiling at every M."""
    out = convergence(lenses.load("ideal"), 8, 12, points=(1, 4, 16), n_plates=2)
    rows = out["by_points"]
    assert [r["points"] for r in rows] == [1, 4, 16]
    assert rows[-1]["plate_ceiling"] < rows[0]["plate_ceiling"]
    assert all(r["rule_plate"] <= r["plate_ceiling"] + 1e-9 for r in rows)


def test_the_chart_draws_the_tighter_ceiling_per_bin_and_the_bracket_to_the_ensemble():
    """A lens panel draws the tighter ceiling as a step over each of its bins and shades, per width bin of
    an entry's ensemble, the bracket from the ensemble's accuracy up to the tighter ceiling of that bin."""
    from matplotlib.collections import PolyCollection

    from benchmark.results.charts.ideal_observer_chart import ideal_observer_figure
    from benchmark.results.entries import make_entry
    from benchmark.results.schema import Units
    tighter = _toy_curve(0.6, (0.55, 0.65), True)
    stored = json.loads((LEADERBOARD / "studies" / "ideal_observer.json").read_text())
    record = {**stored["lenses"]["defocus"], "marginal": {"t1": {"curve": tighter.to_dict()}}}
    study = {**stored, "lenses": {"defocus": record}}
    correct = [1] * 5 + [0] * 15
    row = Row(kind="reader", lens="defocus", attack="lpdr-oracle", reader="lpdr-oracle", seed=0, profile="quick",
              scenes="synthetic", threat_model="sensor-access", metrics={"plate_acc": 0.25, "n_plates": 20.0})
    row.set_units(Units.from_names("plate", [f"synthetic/val/0/{i:05d}@x0y0p0#0" for i in range(20)],
                                   {"correct": correct, "char_errors": [7 * (1 - c) for c in correct],
                                    "width_px": [26] * 20}))
    entry = make_entry("defocus", [row], {}, None, record["lens_spec"])
    panel = next(ax for ax in ideal_observer_figure(study, [entry]).get_axes() if ax.get_title() == "defocus")
    (step,) = [line for line in panel.get_lines() if line.get_linestyle() == "-." and len(line.get_xdata())]
    assert list(step.get_xdata()) == [24.0, 36.0] and list(step.get_ydata()) == pytest.approx([60.0, 60.0])
    bands = [c for c in panel.collections if isinstance(c, PolyCollection) and len(c.get_paths())
             and c.get_paths()[0].vertices.size]
    spans = [(float(v[:, 0].min()), float(v[:, 0].max()), float(v[:, 1].min()), float(v[:, 1].max()))
             for c in bands for v in (c.get_paths()[0].vertices,)]
    assert (24.0, 32.0, 25.0, 60.0) in [tuple(round(x, 6) for x in s) for s in spans]  # bin 24-32: 25 % to 60 %


def test_the_board_brackets_privacy_between_the_ensemble_and_the_tighter_ceiling(planted):
    """The tighter-ceiling column and the bracket sentence give the marginalised ceiling where the study has
    it (the genie's, said so, where not), beside what the ensemble reads of the same plates; the verdict is
    the gap's interval's."""
    from benchmark.publish.tables import bracket_lines, observer_columns
    from benchmark.results.entries import make_entry
    from benchmark.results.schema import Units
    reads, curves = planted["reads"], planted["curves"]
    study, spec = _study(curves)

    def entry(hits: np.ndarray):
        row = Row(kind="reader", attack="honest", reader="honest", threat_model="lens-access", lens="defocus", seed=0,
                  profile="quick", scenes="synthetic", metrics={"plate_acc": float(hits.mean()), "n_plates": 400.0})
        row.set_units(Units.from_names("plate", [f"synthetic/val/0/{i:05d}@x0y0p0#0" for i in range(len(hits))],
                                       {"correct": hits.astype(int).tolist(), "char_errors": [0] * len(hits),
                                        "width_px": [30] * len(hits)}))
        return make_entry("defocus", [row], {}, None, spec)

    tight = curves["marginal"].plate_ceiling[0]
    honest = entry(reads["honest"][:400])
    column = observer_columns(study)[1]
    assert column.header.startswith("tighter ceiling") and column.cell(honest, None)[1] == pytest.approx(100 * tight)
    (line,) = bracket_lines([honest], study)
    assert f"{100 * tight:.1f} %" in line and "tighter ceiling" in line and "within 30 points" in line
    (weak,) = bracket_lines([entry(np.zeros(400, bool))], study)
    assert "between 0.0 %" in weak and ("more than 30 points below" in weak) == (tight > 0.35)
    (few,) = bracket_lines([entry(np.zeros(3, bool))], study)
    assert "cannot tell" in few
    genie_only = {"lenses": {"defocus": {k: v for k, v in study["lenses"]["defocus"].items() if k != "marginal"}}}
    assert column.cell(honest, None)[0] != "not computed" and observer_columns(genie_only)[1].cell(honest, None)[0] == \
        "not computed"
    (genie_line,) = bracket_lines([honest], genie_only)
    assert "genie ceiling" in genie_line
