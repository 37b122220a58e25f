"""The project README's results table is written by `report` from the entries, so it cannot go stale."""

from __future__ import annotations

from pathlib import Path

from benchmark.publish.report import README_END, README_START, readme_results, update_readme
from benchmark.publish.tables import readme_table
from benchmark.publish.versions import board_split
from benchmark.results.entries import LEADERBOARD, display_order, load_entries
from benchmark.results.observer.published import load_study

README = Path(__file__).resolve().parents[3] / "README.md"


def _section(text: str) -> str:
    return text.split(README_START, 1)[1].split(README_END, 1)[0].strip()


def test_the_readme_holds_the_boards_own_short_table():
    text = README.read_text()
    assert README_START in text and README_END in text, "the README lost its results markers"
    entries = display_order(load_entries())
    expected = readme_results(entries, load_study(LEADERBOARD))
    assert _section(text) == expected.strip(), "the README's table is stale: run python -m benchmark report"
    table = readme_table(board_split(entries).current, load_study(LEADERBOARD))
    header = table.splitlines()[0]
    assert header.count("|") - 1 <= 8  # a short table: at most 8 columns
    board = board_split(entries)
    quick = [e.lens for e in board.current if e.profile == "quick"]
    assert [line.split(" | ")[0].strip("| ") for line in table.splitlines()[2:]] == quick  # the quick board only
    for apart in (a.entry.lens for a in board.apart if a.entry.profile == "quick"):  # named, not tabled
        assert apart in expected.split(table, 1)[1]


def test_update_readme_rewrites_only_between_the_markers(tmp_path):
    readme = tmp_path / "README.md"
    readme.write_text(f"before\n{README_START}\nold table\n{README_END}\nafter\n")
    assert update_readme(readme, LEADERBOARD)
    text = readme.read_text()
    assert text.startswith("before\n") and text.endswith(f"{README_END}\nafter\n") and "old table" not in text
    assert _section(text) == readme_results(display_order(load_entries()), load_study(LEADERBOARD)).strip()
    readme.write_text("no markers\n")
    assert not update_readme(readme, LEADERBOARD) and readme.read_text() == "no markers\n"
