"""The leaderboard's trade-off table (benchmark.publish.tables) against the entries it is rendered from.

The ensemble's plate cell is checked against an independent Wilson interval (scipy), the table's shape
against its column definitions, and a plugin's name with Markdown in it against the layout it could break.
"""

from __future__ import annotations

import dataclasses

import pytest
from scipy.stats import binomtest

from benchmark.publish.tables import (ENSEMBLE_PLATES, contributions_table, main_table, table_columns)
from benchmark.results.ensemble import plate_ensemble
from benchmark.results.entries import LEADERBOARD, read_entry

ENTRIES = ("gp__quick__synthetic.json", "ideal__smoke__synthetic.json")


def cells(line: str) -> list[str]:
    return [c.strip() for c in line.strip().strip("|").split(" | ")]


@pytest.fixture(scope="module")
def entries():
    return [read_entry(LEADERBOARD / "entries" / name) for name in ENTRIES]


@pytest.mark.slow
def test_one_line_per_entry_and_one_cell_per_column(entries):
    columns = table_columns(None, entries)
    lines = main_table(entries).splitlines()
    assert cells(lines[0]) == [c.header for c in columns]
    assert lines[1] == "|" + "|".join(["---"] * len(columns)) + "|"
    assert len(lines) == 2 + len(entries)
    assert [cells(line)[0] for line in lines[2:]] == [e.lens for e in entries]
    assert all(len(cells(line)) == len(columns) for line in lines[2:])


@pytest.mark.slow
def test_the_ensemble_cell_is_its_pooled_reads_with_a_wilson_interval(entries):
    header = cells(main_table(entries).splitlines()[0])
    for entry, line in zip(entries, main_table(entries).splitlines()[2:]):
        accuracy = plate_ensemble(entry.rows).accuracy
        low, high = binomtest(accuracy.hits, accuracy.n).proportion_ci(confidence_level=0.95, method="wilson")
        cell = dict(zip(header, cells(line)))[ENSEMBLE_PLATES]
        assert cell.startswith(f"{100 * accuracy.hits / accuracy.n:.1f} [{100 * low:.1f}, {100 * high:.1f}]"), cell


def test_contributions_add_up_to_the_ensemble(entries):
    entry = entries[0]
    ensemble = plate_ensemble(entry.rows)
    lines = contributions_table([entry]).splitlines()[2:]
    assert lines and all(cells(line)[0] == entry.lens for line in lines)
    # Every plate only one chain read is one of the ensemble's reads, and each share is of the ensemble's hits.
    only = sum(int(cells(line)[6].split()[0]) for line in lines)
    assert only <= ensemble.accuracy.hits
    for line in lines:
        read, of = (int(x) for x in cells(line)[5].split(" (")[0].split(" / "))
        assert of == ensemble.accuracy.hits and 0 < read <= of


def test_a_lens_name_with_markdown_keeps_the_table_in_shape(entries):
    hostile = dataclasses.replace(entries[1], lens="evil | lens\n# heading")
    lines = main_table([hostile]).splitlines()
    assert len(lines) == 3 and len(cells(lines[2])) == len(table_columns(None, [hostile]))
