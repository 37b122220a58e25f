"""Lens and attacker names (and plugins' error messages) are inert in the Markdown tables, as they are
on the web page: the leaderboard README, the project README's table, a run's table.md."""

from __future__ import annotations

import re

import pytest

from benchmark.publish import leaderboard
from benchmark.results.markdown import md_cell, md_code
from benchmark.results.run_tables import sectioned_markdown
from benchmark.results.schema import Row, RowError
from benchmark.store.profiles import get_profile

SCRIPT = "<script>alert(1)</script>"
IMG = '<img src=x onerror="alert(1)">'
LINK = "[click](javascript:alert(1))"
HOSTILE = (SCRIPT, IMG, LINK, "a|b", "two\nlines", "back\\", "<!-- hide", "<https://evil.example>")


def _inert(markdown: str) -> None:
    """No tag, comment or autolink can open and no link closes: what a renderer would act on."""
    assert not re.search(r"<[A-Za-z/!?]", markdown), markdown
    assert not re.search(r"(?<!\\)\]\(", markdown), markdown


def _rows(lens: str, attack: str) -> list[Row]:
    ids = {"lens": lens, "seed": 0, "profile": "smoke", "scenes": "synthetic"}
    return [Row(kind="utility", attack="utility", metrics={"miou": 0.3}, **ids),
            Row(kind="restorer", attack=attack, restorer=attack, metrics={"psnr_db": 20.0, "ssim": 0.5}, **ids),
            Row.failed("restorer", attack="crash", restorer="crash",
                       error=RowError("crash", "restore", f"{IMG} | second cell\n{SCRIPT}"), **ids)]


@pytest.mark.parametrize("text", HOSTILE)
def test_a_cell_is_inert_and_keeps_its_text(text):
    cell = md_cell(text)
    _inert(cell)
    assert "\n" not in cell and not re.search(r"(?<!\\)\|", cell)  # one cell of one row
    # Undoing the escapes gives back what was shown, line breaks as spaces.
    shown = re.sub(r"\\(.)", r"\1", cell.replace("&lt;", "<"))
    assert shown == text.replace("\n", " ")


def test_ordinary_cells_are_unchanged():
    for text in ("identity>lpdr-oracle", "< 0.001", "+0.043 [+0.039, +0.048]", "26.47 ± 0.53 (wiener-known-psf)",
                 "os-d-1", "yes (1/2 seeds: Z3 tilt y in 1)"):
        assert md_cell(text) == text


def test_code_spans_hold_backticks():
    assert md_code("smoke") == "`smoke`"
    assert md_code("a`<b>`") == "`` a`<b>` ``"


def test_the_leaderboard_readme_shows_hostile_names_inert(tmp_path):
    board, run = tmp_path / "board", tmp_path / "run"
    run.mkdir()
    profile = get_profile("smoke").to_dict()
    for lens, attack in ((SCRIPT, IMG), (LINK, "x|y")):
        leaderboard.publish_run(_rows(lens, attack), profile, {}, run, board)
    readme = (board / "README.md").read_text()
    tables = [[line for line in block.splitlines() if line.startswith("|")] for block in readme.split("\n\n")]
    tables = [lines for lines in tables if lines]
    text = "\n".join(line for lines in tables for line in lines)
    _inert(text)
    assert f"| {md_cell(SCRIPT)} |" in text and md_cell(IMG) in text and md_cell(LINK) in text
    # Every line of a table has its header's number of cells: no name opened a cell or a row.
    for lines in tables:
        assert len({len(re.findall(r"(?<!\\)\|", line)) for line in lines}) == 1, lines


def test_the_run_table_shows_hostile_names_and_errors_inert():
    text = sectioned_markdown(_rows(SCRIPT, IMG) + _rows(LINK, "x|y"))
    _inert(text)
    failed = text.split("### Failed attackers")[1]
    assert md_cell(f"{IMG} | second cell") in failed and "alert(1)</script>" not in failed
    assert md_cell(SCRIPT) in text and md_cell(LINK) in text
