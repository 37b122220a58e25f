"""A run's table.md / table.csv (benchmark.results.run_tables), on the rows of a published smoke entry
(real rows, every row kind, three seeds): intervals shown, chains labelled by their strongest part,
every line a chart draws present in the table."""

import json
import math
from pathlib import Path

import pandas as pd
import pytest

import attacks
from benchmark.results import run_tables
from benchmark.results.charts.plate_width import width_accuracy
from benchmark.results.charts.restorers import restorer_points
from benchmark.results.entries import Entry
from benchmark.results.schema import Row, threat_models

ENTRY = Path(__file__).resolve().parents[3] / "leaderboard" / "entries" / "defocus__smoke__synthetic.json"


@pytest.fixture(scope="module")
def rows() -> list[Row]:
    return Entry.from_json(json.loads(ENTRY.read_text())).rows


def written(tmp_path: Path, rows: list[Row]) -> tuple[pd.DataFrame, str]:
    run_tables.write_tables(tmp_path, rows)
    return pd.read_csv(tmp_path / "table.csv"), (tmp_path / "table.md").read_text()


def md_lines(md: str) -> dict[tuple[str, str], dict[str, str]]:
    """(lens, attack) -> {column header: cell} over every section of table.md."""
    out: dict[tuple[str, str], dict[str, str]] = {}
    head: list[str] = []
    for line in md.splitlines():
        if not line.startswith("|") or line.startswith("|:") or line.startswith("|-"):
            continue
        cells = [c.strip() for c in line.strip("|").split("|")]
        if cells[:2] == ["lens", "attack"]:
            head = cells
            continue
        out.setdefault((cells[0], cells[1]), {}).update(zip(head, cells))
    return out


def test_csv_carries_every_rows_own_interval(tmp_path, rows):
    table, _ = written(tmp_path, rows)
    assert len(table) == len(rows)
    checked = 0
    for (_, line), row in zip(table.iterrows(), rows):
        assert (line["lens"], line["attack"], line["seed"]) == (row.lens, row.attack, row.seed)
        for name, (low, high) in row.intervals.items():
            assert line[f"{name}_ci_low"] == pytest.approx(low, abs=0) and line[f"{name}_ci_high"] == pytest.approx(high, abs=0)
            checked += 1
        for name in set(row.metrics) - set(row.intervals):
            if f"{name}_ci_low" in table.columns:
                assert math.isnan(line[f"{name}_ci_low"])
    assert checked > 40  # every row's intervals (66 on the entry of the standard ensemble)


def test_markdown_shows_each_metric_with_its_interval(tmp_path, rows):
    seed0 = [r for r in rows if r.seed == 0]
    _, md = written(tmp_path, seed0)
    lines = md_lines(md)
    fmt = run_tables._fmt
    shown = 0
    for row in seed0:
        cells = lines.get((row.lens, row.attack), {})
        for name, (low, high) in row.intervals.items():
            if name in cells:
                assert cells[name] == f"{fmt(row.metrics[name])} [{fmt(low)}, {fmt(high)}]"
                shown += 1
    assert shown > 15 and "95 % interval" in md


def test_markdown_interval_over_seeds_spans_every_seeds_interval(tmp_path, rows):
    _, md = written(tmp_path, rows)
    cells = md_lines(md)[("defocus", "nafnet-known-psf")]
    mine = [r for r in rows if r.attack == "nafnet-known-psf"]
    low = min(r.intervals["psnr_db"][0] for r in mine)
    high = max(r.intervals["psnr_db"][1] for r in mine)
    mean = sum(r.metrics["psnr_db"] for r in mine) / len(mine)
    fmt = run_tables._fmt
    assert cells["psnr_db"] == f"{fmt(mean)} [{fmt(low)}, {fmt(high)}]"
    assert float(cells["psnr_db seed sd"]) == pytest.approx(pd.Series([r.metrics["psnr_db"] for r in mine]).std(),
                                                            abs=1e-3)


def test_chain_threat_model_is_the_strongest_of_its_parts(tmp_path, rows):
    order = list(attacks.ThreatModel)
    for a in order:
        for b in order:
            assert attacks.ThreatModel.strongest(a, b) == max(a, b, key=order.index)
            assert attacks.ThreatModel.strongest(a.value, b) in (a, b)
    assert attacks.ThreatModel.strongest("sensor-access", "known-pairs", "lens-access") is attacks.ThreatModel.LENS_ACCESS
    # The stored rows label every chain with its reader's threat model; tables relabel them.
    own = {r.attack: r.threat_model for r in rows}
    labels = threat_models(rows)
    table, md = written(tmp_path, rows)
    lines = md_lines(md)
    chains = [r for r in rows if r.restorer and r.reader and r.ok]
    assert chains
    for r in chains:
        expected = attacks.ThreatModel.strongest(own[r.restorer], own[r.reader]).value
        assert labels[r.attack] == expected
        assert lines[(r.lens, r.attack)]["threat_model"] == expected
        assert set(table[table["attack"] == r.attack]["threat_model"]) == {expected}
    # The entry holds the standard ensemble's chain: a lens-access restorer before the sensor-access lpdr.
    assert labels["nafnet-known-psf>lpdr"] == "lens-access"


def test_every_line_a_chart_draws_is_in_the_table(tmp_path, rows):
    _, md = written(tmp_path, rows)
    lines = md_lines(md)
    # plates.csv-like records: one per readable plate a reader or chain scored (the plate-width chart's input).
    records = [{"lens": r.lens, "attack": r.attack, "width_px": 40.0, "correct": i < r.metrics["plate_acc"] * 2}
               for r in rows if r.ok and r.metric("n_plates") for i in range(int(r.metrics["n_plates"]))]
    charted = set(width_accuracy(records)) | set(restorer_points(rows))
    assert ("defocus", "nafnet-known-psf>lpdr") in charted
    assert charted - set(lines) == set()
