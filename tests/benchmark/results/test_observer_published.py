"""The ideal-observer study on the leaderboard and in a run: columns only for the same lens, and a
reader above the ceiling reported loudly (README, web page, ERROR log, ceiling_check.json)."""

from __future__ import annotations

import json
import logging
from pathlib import Path

import pytest

from benchmark.publish import report as leaderboard_report
from benchmark.publish.leaderboard import publish
from benchmark.results.entries import LEADERBOARD, load_entries
from benchmark.publish.tables import main_table
from benchmark.results.observer import published
from benchmark.results.observer.ceiling import Precision, ceiling_curve
from benchmark.studies.observer_study import summary
from benchmark.store.profiles import get_profile
from benchmark.results.schema import Row
from lenses import Lens, parse_spec

pytestmark = pytest.mark.slow  # ideal-observer ceilings of a lens, computed (5-7 s each)

STUDY = json.loads((LEADERBOARD / "studies" / "ideal_observer.json").read_text())
DEFOCUS_SPEC = STUDY["lenses"]["defocus"]["lens_spec"]


def reader_row(lens: str, attack: str, accuracy: float, n_plates: int, seed: int = 0) -> Row:
    return Row(kind="reader", attack=attack, reader=attack, threat_model="lens-access", lens=lens, seed=seed,
               profile="quick", scenes="synthetic", metrics={"plate_acc": accuracy, "n_plates": float(n_plates)})


def columns(text: str, row_start: str) -> dict[str, str]:
    """The cells of the first table row starting with `row_start` in markdown `text`, by the header of
    its table (the line above the table's |---| rule)."""
    lines = text.splitlines()
    at = next(i for i, x in enumerate(lines) if x.startswith(row_start))
    rule = max(i for i in range(at) if lines[i].startswith("|-") or lines[i].startswith("| -"))
    head = [c.strip() for c in lines[rule - 1].strip("|").split("|")]
    cells = [c.strip() for c in lines[at].strip("|").split("|")]
    assert len(head) == len(cells), (head, cells)
    return dict(zip(head, cells))


CEILING, TIGHTER = "ceiling % at 32 px (ideal observer, T=1)", "tighter ceiling % [95 %] at 32-48 px (T=1)"
W5_T1, W5_T30 = "W_5% px (ideal observer, T=1)", "W_5% px (ideal observer, T=30)"


def board(tmp_path: Path, spec: dict, accuracy: float, lens: str = "defocus", study: dict = STUDY) -> Path:
    """A leaderboard folder with `study` and one entry of `lens` (given spec) whose reader reads `accuracy`
    of 300 plates (two seeds)."""
    (tmp_path / "entries").mkdir()
    (tmp_path / "studies").mkdir()
    (tmp_path / "studies" / "ideal_observer.json").write_text(json.dumps(study))
    rows = [Row(kind="utility", attack="utility", lens=lens, seed=0, profile="quick", scenes="synthetic",
                metrics={"miou": 0.2}),
            reader_row(lens, "answer-key", accuracy, 200), reader_row(lens, "answer-key", accuracy, 100, 1)]
    publish(rows, get_profile("quick").to_dict(), {lens: {"spec": spec, "coefficients_um": [0.0] * 6}}, tmp_path)
    return tmp_path


@pytest.fixture(scope="module")
def near_focus() -> tuple[dict, dict]:
    """A lens focused at 0.5 m (an 87 px PSF) and a study holding its computed ceiling at 32 and 48 px,
    well below 100 % (every readable plate of the quick lenses is legible to the ideal observer, so a
    lens this blurred is needed for a ceiling a reader of readable plates can beat)."""
    spec = json.loads(json.dumps(DEFOCUS_SPEC))
    spec["name"], spec["optics"]["focus_distance_m"] = "near-focus", 0.5
    coarse = Precision(interval_width=0.1, coarse_width=0.2, min_plates=4, batch=4, max_plates=8)
    curve = ceiling_curve(Lens(parse_spec(spec, source="test")), (32, 48), frames=1, precision=coarse, pair=None)
    study = {**STUDY, "lenses": {"near-focus": {"lens_spec": spec, "t1": summary(curve)}}}
    return spec, study


def test_a_reader_above_the_ceiling_is_reported_in_the_readme_the_page_and_the_log(tmp_path, caplog, near_focus):
    spec, study = near_focus
    assert study["lenses"]["near-focus"]["t1"]["curve"]["plate_interval"][-1][1] < 0.9
    directory = board(tmp_path, spec, 1.0, "near-focus", study)
    with caplog.at_level(logging.ERROR):
        leaderboard_report.render(directory)
    readme = (directory / "README.md").read_text()
    section = readme.split("## Ceiling violations", 1)[1].split("## ", 1)[0]
    assert "1 reader(s) beat the ideal observer's ceiling" in section and "answer-key" in section
    assert "| near-focus | quick | synthetic | answer-key | 100.0 |" in section
    page = (directory / "index.html").read_text()
    assert "Ceiling violations" in page and 'class="violation"' in page and "answer-key" in page
    assert any("CEILING VIOLATION" in r.message and "answer-key" in r.message and r.levelno == logging.ERROR
               for r in caplog.records)
    # The columns of what the study lacks (T = 30, the marginalised curve) read "not computed"; the
    # others show the study.
    cells = columns(readme, "| near-focus | quick")
    assert [h for h, c in cells.items() if c == "not computed"] == [TIGHTER, W5_T30]
    assert cells[CEILING] == f"{100 * study['lenses']['near-focus']['t1']['plate_ceiling_w32']:.1f}"


def test_a_reader_below_the_ceiling_passes(tmp_path, caplog, near_focus):
    spec, study = near_focus
    with caplog.at_level(logging.ERROR):
        leaderboard_report.render(board(tmp_path, spec, 0.3, "near-focus", study))
    assert not [r for r in caplog.records if "CEILING VIOLATION" in r.message]


def test_an_honest_reader_passes_and_the_columns_show_the_study(tmp_path, caplog):
    directory = board(tmp_path, DEFOCUS_SPEC, 0.0)
    with caplog.at_level(logging.ERROR):
        leaderboard_report.render(directory)
    assert not [r for r in caplog.records if "CEILING VIOLATION" in r.message]
    readme = (directory / "README.md").read_text()
    assert "None: every reader" in readme.split("## Ceiling violations", 1)[1]
    t1 = STUDY["lenses"]["defocus"]["t1"]
    cells = columns(readme, "| defocus | quick")
    assert (cells[CEILING], cells[W5_T1], cells[W5_T30]) == (
        f"{100 * t1['plate_ceiling_w32']:.1f}", str(t1["w5_plate_px"]), str(STUDY["lenses"]["defocus"]["t30"]["w5_plate_px"]))
    assert cells[TIGHTER].endswith("]") and "not computed" not in cells.values()


def test_another_spec_of_the_same_name_is_not_computed_and_not_checked(tmp_path, caplog):
    """A retrained lens keeps its name; the study's ceiling is of the old coefficients: not shown, not checked."""
    changed = json.loads(json.dumps(DEFOCUS_SPEC))
    changed["mask"]["zernike_um"][3] = 0.25
    directory = board(tmp_path, changed, 1.0)
    with caplog.at_level(logging.ERROR):
        leaderboard_report.render(directory)
    assert not [r for r in caplog.records if "CEILING VIOLATION" in r.message]
    table = main_table(load_entries(directory), published.load_study(directory)).splitlines()
    head = [c.strip() for c in table[0].strip("|").split("|")]
    line = [c.strip() for c in next(x for x in table if x.startswith("| defocus")).strip("|").split("|")]
    # The three ideal-observer columns and the attack gap (ceiling - ensemble) need the study's ceiling.
    assert [h for h, c in zip(head, line) if c == "not computed"] == [
        CEILING, TIGHTER, W5_T1, W5_T30, "attack gap pt at 32 px (ceiling - ensemble)"]


def test_specs_compare_by_value_not_description():
    same = {**DEFOCUS_SPEC, "description": "reworded"}
    assert published.same_lens(DEFOCUS_SPEC, same)
    nudged = json.loads(json.dumps(DEFOCUS_SPEC))
    nudged["optics"]["focus_distance_m"] += 1e-3
    assert not published.same_lens(DEFOCUS_SPEC, nudged)
    assert not published.same_lens(None, DEFOCUS_SPEC)


def test_a_run_writes_its_check_per_width_bin(tmp_path, caplog, near_focus):
    """Per-plate records of a run: the 32-48 px bin of near-focus read perfectly trips; ideal (ceiling
    100 %) passes; a lens the study lacks is named as not checked."""
    spec, study = near_focus
    (tmp_path / "studies").mkdir()
    both = {**study, "lenses": {**study["lenses"], "ideal": STUDY["lenses"]["ideal"]}}
    (tmp_path / "studies" / "ideal_observer.json").write_text(json.dumps(both))
    records = ([{"lens": "near-focus", "attack": "answer-key", "width_px": 33 + i % 10, "correct": "True"}
                for i in range(100)]
               + [{"lens": "ideal", "attack": "answer-key", "width_px": 40, "correct": True} for _ in range(400)]
               + [{"lens": "os-d-1", "attack": "answer-key", "width_px": 40, "correct": True} for _ in range(50)])
    info = {"near-focus": {"spec": spec}, "ideal": {"spec": STUDY["lenses"]["ideal"]["lens_spec"]},
            "os-d-1": {"spec": {}}}
    out = tmp_path / "run"
    out.mkdir()
    with caplog.at_level(logging.ERROR):
        path = published.write_run_check(out, records, info, tmp_path)
    check = json.loads(path.read_text())
    assert path == out / "ceiling_check.json"
    assert check["checked"] == ["ideal", "near-focus"] and "os-d-1" in check["not_checked"]
    assert [(v["lens"], v["low_px"], v["high_px"]) for v in check["violations"]] == [("near-focus", 32, 48)]
    assert check["violations"][0]["ceiling_high"] < 0.9
    assert any("CEILING VIOLATION" in r.message for r in caplog.records)


def test_entry_accuracy_pools_seeds_with_a_wilson_interval():
    from scipy.stats import binomtest
    (entry,) = [e for e in load_entries(LEADERBOARD) if e.lens == "gp" and e.profile == "quick"]
    chain = next(c for c in entry.chains() if c.attack == "wiener-known-psf>lpdr-oracle")
    hits = sum(round(r.metrics["plate_acc"] * r.metrics["n_plates"]) for r in chain.rows)
    n = sum(int(r.metrics["n_plates"]) for r in chain.rows)
    (m,) = [m for m in published.entry_accuracies(entry) if m.reader == chain.attack]
    ci = binomtest(hits, n).proportion_ci(0.95, method="wilson")
    assert m.n_plates == n and m.accuracy == pytest.approx(hits / n)
    assert m.interval == pytest.approx((ci.low, ci.high), abs=1e-9)


def test_specs_compare_as_the_lens_code_parses_them():
    """A spec stored without the obsolete `simulation.oversample` (smoke entries) or with a default
    spelled out is the same lens; one that no longer parses is no lens the study covers."""
    assert "oversample" in DEFOCUS_SPEC["simulation"]
    without = json.loads(json.dumps(DEFOCUS_SPEC))
    del without["simulation"]["oversample"]
    assert published.same_lens(DEFOCUS_SPEC, without) and published.same_lens(without, DEFOCUS_SPEC)
    spelled_out = parse_spec(without, source="test").to_dict()
    assert published.same_lens(DEFOCUS_SPEC, spelled_out)
    broken = {**without, "optics": {**without["optics"], "focal_length": 25.0}}
    assert not published.same_lens(DEFOCUS_SPEC, broken)


def test_the_smoke_entries_carry_the_study_columns():
    """The published smoke entries of ideal and defocus (stored without `simulation.oversample`) show
    the study's ceiling, not "not computed"."""
    entries = [e for e in load_entries(LEADERBOARD) if e.profile == "smoke" and e.lens in ("ideal", "defocus")]
    assert {e.lens for e in entries} == {"ideal", "defocus"}
    table = main_table(entries, STUDY)
    for lens in ("ideal", "defocus"):
        cells = columns(table, f"| {lens} | smoke")
        t1 = STUDY["lenses"][lens]["t1"]
        assert "not computed" not in cells.values()
        assert (cells[CEILING], cells[W5_T1]) == (f"{100 * t1['plate_ceiling_w32']:.1f}", str(t1["w5_plate_px"]))


def test_the_reader_study_checks_every_bin_against_the_ceiling(caplog, near_focus):
    """A reader of the reader study that reads every 32-48 px plate of a lens whose ceiling there is
    below 90 % trips the check (logged as an error, kept in the record); one that reads none passes."""
    from benchmark.studies.reader_study import summarise
    spec, study = near_focus
    records = [{"lens": "near-focus", "attack": reader, "width_px": 33 + i % 10, "correct": reader == "answer-key",
                "truth": "AB123CD", "read": "AB123CD" if reader == "answer-key" else ""}
               for reader in ("answer-key", "lpdr-oracle") for i in range(40)]
    with caplog.at_level(logging.ERROR):
        out = summarise(records, {"near-focus": spec}, study)
    assert [v["reader"] for v in out["consistency"]["violations"]] == ["answer-key"]
    assert any("CEILING VIOLATION" in r.message and "answer-key" in r.message for r in caplog.records)
    (cheat,) = out["lenses"]["near-focus"]["answer-key"]["bins"]
    assert (cheat["low_px"], cheat["high_px"], cheat["n_plates"], cheat["accuracy"]) == (32, 48, 40, 1.0)
    assert cheat["interval"][0] == pytest.approx(40 / (40 + 1.959963984540054**2))  # Wilson at 40 of 40


def test_the_chart_draws_the_reader_study_per_width_bin(tmp_path):
    from benchmark.results.charts.ideal_observer_chart import ideal_observer_figure, write_ideal_observer_chart
    bins = [{"low_px": 32, "high_px": 48, "accuracy": 0.25, "interval": [0.1, 0.5], "n_plates": 12},
            {"low_px": 192, "high_px": None, "accuracy": 0.75, "interval": [0.4, 0.9], "n_plates": 4}]
    readers = {"lens_specs": {"defocus": DEFOCUS_SPEC}, "lenses": {"defocus": {"ideal-observer": {"bins": bins}}}}
    fig = ideal_observer_figure(STUDY, (), readers)
    panel = next(ax for ax in fig.get_axes() if ax.get_title() == "defocus")
    drawn = sorted((round(float(line.get_xdata()[0]), 3), float(line.get_ydata()[0])) for line in panel.get_lines()
                   if line.get_marker() == "s" and len(line.get_xdata()))
    assert drawn == [(round(1.03 * (32 * 48) ** 0.5, 3), 25.0), (round(1.03 * 1.25 * 192, 3), 75.0)]
    other = {**readers, "lens_specs": {"defocus": {**DEFOCUS_SPEC, "optics": {**DEFOCUS_SPEC["optics"],
                                                                              "focus_distance_m": 3.0}}}}
    panel = next(ax for ax in ideal_observer_figure(STUDY, (), other).get_axes() if "defocus" in ax.get_title())
    assert panel.get_title() == "defocus (no matching entry)"
    (tmp_path / "studies").mkdir()
    (tmp_path / "studies" / "ideal_observer_readers.json").write_text(json.dumps(readers))
    assert write_ideal_observer_chart(STUDY, (), tmp_path / "charts" / "ideal_observer.png").is_file()


def test_a_run_check_says_in_one_line_what_it_checked_and_why_not_the_rest(tmp_path):
    """ceiling_check.json's `summary`: the lenses checked, and per skipped lens why, naming the spec
    fields that differ from the study's (the main job's shipped gp lens vs a study of another gp)."""
    (tmp_path / "studies").mkdir()
    (tmp_path / "studies" / "ideal_observer.json").write_text(json.dumps(STUDY))
    moved = json.loads(json.dumps(DEFOCUS_SPEC))
    moved["optics"]["focus_distance_m"] = 0.5
    info = {"ideal": {"spec": STUDY["lenses"]["ideal"]["lens_spec"]}, "defocus": {"spec": moved},
            "my-lens": {"spec": DEFOCUS_SPEC}}
    records = [{"lens": "ideal", "attack": "answer-key", "width_px": 40, "correct": True} for _ in range(20)]
    out = tmp_path / "run"
    out.mkdir()
    check = json.loads(published.write_run_check(out, records, info, tmp_path).read_text())
    summary = check["summary"]
    assert "\n" not in summary and list(check)[0] == "summary"
    assert summary.startswith(f"checked ideal in {check['bins_checked']} width bin(s): 0 violation(s)")
    assert "defocus not checked: the study's lens spec differs from this run's in optics.focus_distance_m" in summary
    assert "my-lens not checked: no ideal-observer curve for this lens" in summary
    assert check["not_checked"]["defocus"].endswith("optics.focus_distance_m")
    nothing = published.run_violations(records, {"defocus": {"spec": moved}}, STUDY)["summary"]
    assert nothing.startswith("nothing checked; defocus not checked")


def test_the_chart_draws_an_entrys_ensemble_per_width_bin_against_the_ceiling():
    """An entry whose plates carry widths draws its ensemble (a plate read by any chain) per width bin at the
    bins' centres, with Wilson intervals; a bin of fewer than MIN_BIN_PLATES plates is left out; an entry
    without widths keeps its readers' pooled points."""
    import math

    from benchmark.results import stats
    from benchmark.results.charts.ideal_observer_chart import MIN_BIN_PLATES, ideal_observer_figure
    from benchmark.results.entries import make_entry
    from benchmark.results.schema import Units
    widths = [40] * 20 + [100] * 20 + [20] * (MIN_BIN_PLATES - 1)  # bins 32-48, 96-128 and a thin 16-24
    a = [1] * 5 + [0] * 15 + [1] * 10 + [0] * 10 + [1] * (MIN_BIN_PLATES - 1)
    b = [0] * 5 + [1] * 5 + [0] * 10 + [0] * 20 + [0] * (MIN_BIN_PLATES - 1)

    def panel_of(with_widths: bool):
        rows = []
        for attack, correct in (("lpdr-oracle", a), ("identity>lpdr-oracle", b)):
            names = [f"synthetic/val/0/{i:05d}@x0y0p0#0" for i in range(len(correct))]
            restorer, reader = attack.split(">") if ">" in attack else (None, attack)
            row = Row(kind="chain" if restorer else "reader", lens="defocus", attack=attack, restorer=restorer,
                      reader=reader, seed=0, profile="quick", scenes="synthetic", threat_model="sensor-access",
                      metrics={"plate_acc": sum(correct) / len(correct), "n_plates": float(len(correct))})
            values = {"correct": correct, "char_errors": [7 * (1 - c) for c in correct]}
            row.set_units(Units.from_names("plate", names, {**values, "width_px": widths} if with_widths else values))
            rows.append(row)
        entry = make_entry("defocus", rows, {}, None, DEFOCUS_SPEC)
        return next(ax for ax in ideal_observer_figure(STUDY, [entry]).get_axes() if ax.get_title() == "defocus")

    panel = panel_of(with_widths=True)
    (curve,) = [c for c in panel.containers if c.lines[0].get_marker() == "D"]
    xs, ys = (list(map(float, v)) for v in curve.lines[0].get_data())
    assert xs == pytest.approx([math.sqrt(32 * 48), math.sqrt(96 * 128)])
    assert ys == pytest.approx([50.0, 50.0])  # 10 of 20 read by either chain in each bin
    low, high = stats.wilson_interval(10, 20)
    (bars,) = curve.lines[2]
    spans = [float(v) for seg in bars.get_segments() for v in seg[:, 1]]
    assert spans == pytest.approx([100 * low, 100 * high] * 2)
    assert "ensemble of 2 chains" in " ".join(t.get_text() for t in panel.get_legend().get_texts())
    # The same entry without widths: each reader's pooled point, no ensemble curve.
    panel = panel_of(with_widths=False)
    assert not [c for c in panel.containers if c.lines[0].get_marker() == "D"]
    assert len([c for c in panel.containers if c.lines[0].get_marker() == "o"]) == 2
