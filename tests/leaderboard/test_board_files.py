"""Everything under leaderboard/ is an entry, a study, or written by `report` from them."""

from __future__ import annotations

import re
import shutil
from pathlib import Path

import numpy as np
import pytest
from PIL import Image

from benchmark.results.plate_scoring import READABLE_MIN_WIDTH_PX
from benchmark.publish import board_files
from benchmark.publish import report as leaderboard_report
from benchmark.publish.leaderboard import publish
from benchmark.results.entries import LEADERBOARD, LOCK_FILE, load_entries
from benchmark.results.schema import Row, Units
from benchmark.store.profiles import get_profile

LINK = re.compile(r"""(?:\]\(|src=")((?:charts|samples)/[^)"\s]+)""")


def _referenced(directory: Path) -> set[Path]:
    """The charts/ and samples/ files the rendered pages link (README.md, attackers.md, charts.md, index.html)."""
    found = set()
    for page in ("README.md", board_files.ATTACKERS_PAGE, board_files.CHARTS_PAGE, "index.html"):
        found |= {directory / m for m in LINK.findall((directory / page).read_text())}
    return found


def _unbacked(directory: Path) -> list[Path]:
    """Files under `directory` that are neither an entry, a study, a rendered page nor linked from one."""
    pages = {directory / n for n in ("README.md", board_files.ATTACKERS_PAGE, board_files.CHARTS_PAGE, "index.html")}
    linked = _referenced(directory)
    out = []
    for path in sorted(p for p in directory.rglob("*") if p.is_file()):
        top = path.relative_to(directory).parts[0]
        if top in ("entries", "studies", LOCK_FILE) or path in pages or path in linked:
            continue
        out.append(path)
    return out


def test_every_file_of_the_published_leaderboard_is_backed():
    assert not _unbacked(LEADERBOARD), "orphans under leaderboard/: run python -m benchmark report"
    missing = [p for p in _referenced(LEADERBOARD) if not p.is_file()]
    assert not missing, f"pages link files that do not exist: {missing}"


def test_the_web_page_shows_every_sample_picture_those_shown_apart_marked():
    page = (LEADERBOARD / "index.html").read_text()
    linked = set(LINK.findall(page))
    unshown = [p.name for p in (LEADERBOARD / "samples").glob("*.png") if f"samples/{p.name}" not in linked]
    assert not unshown, f"sample pictures the web page does not show: {unshown}"
    assert "(shown apart: another version)</summary>" in page  # the quick board shows seven entries apart


def test_the_readme_is_short_and_the_attacker_table_has_its_own_page():
    readme = (LEADERBOARD / "README.md").read_text()
    attackers = (LEADERBOARD / board_files.ATTACKERS_PAGE).read_text()
    assert "## Every attacker" not in readme and "## Every attacker" in attackers
    assert f"]({board_files.ATTACKERS_PAGE})" in readme and f"]({board_files.CHARTS_PAGE})" in readme
    assert "![" not in readme, "the README links its charts' page instead of showing every image"
    assert "## Utility against privacy" in readme
    # Every attack chain of every entry has a line on the attackers page.
    for entry in load_entries():
        for chain in entry.chains():
            if chain.kind not in ("lens", "utility", "bound"):
                assert f"| {entry.lens} | {chain.attack} |" in attackers, (entry.lens, chain.attack)


ORPHANS = ("samples/plate_width__quick__gp+os.png",  # one chart per historical run
           "samples/no-such-lens__quick.png",  # a sample of a lens without an entry
           "charts/retired_chart.png",  # a chart kind report no longer draws
           "charts/old/x.png")


@pytest.fixture(scope="module")
def rendered(tmp_path_factory) -> Path:
    """The published board rendered once (a whole render takes minutes) into a copy that holds its entries,
    studies and sample pictures but none of its charts, with orphans planted beside them."""
    copy = tmp_path_factory.mktemp("board") / "leaderboard"
    shutil.copytree(LEADERBOARD, copy, ignore=shutil.ignore_patterns("*.png"))
    for folder in ("charts", "samples"):  # only the sample pictures are inputs; charts are re-drawn
        (copy / folder).mkdir(exist_ok=True)
    for path in (LEADERBOARD / "samples").glob("*.png"):
        shutil.copyfile(path, copy / "samples" / path.name)
    for name in ORPHANS:
        (copy / name).parent.mkdir(parents=True, exist_ok=True)
        Image.fromarray(np.zeros((4, 4), dtype=np.uint8)).save(copy / name)
    leaderboard_report.render(copy)
    return copy


@pytest.mark.slow
def test_the_pages_and_charts_regenerate_identically_from_the_entries(rendered):
    """`python -m benchmark report` gives the published board byte for byte: every page, and every chart
    drawn afresh (none was copied in), no chart more or fewer."""
    charts = sorted(p.relative_to(LEADERBOARD) for p in (LEADERBOARD / "charts").glob("*.png"))
    assert sorted(p.relative_to(rendered) for p in (rendered / "charts").glob("*.png")) == charts, \
        "report draws other charts than are published; run python -m benchmark report"
    for name in ["README.md", board_files.ATTACKERS_PAGE, board_files.CHARTS_PAGE, "index.html", *charts]:
        published, path = LEADERBOARD / name, rendered / name
        assert published.is_file(), f"{published} is not published; run python -m benchmark report"
        assert path.read_bytes() == published.read_bytes(), f"{published} differs from its entries"


@pytest.mark.slow
def test_render_deletes_an_orphan_and_a_stale_image(rendered):
    for name in ORPHANS:
        assert not (rendered / name).exists(), f"{name} survived the render"
    assert (rendered / "samples" / "gp__quick.png").is_file(), "a sample of a published entry was deleted"
    assert not _unbacked(rendered)
    assert all(p.is_file() for p in _referenced(rendered))


def _plates(attack: str, correct: list[int], widths: list[float]) -> Row:
    restorer, _, reader = attack.rpartition(">")
    return Row(kind="chain" if restorer else "reader", attack=attack, restorer=restorer or None, reader=reader,
               lens="gp", seed=0, profile="quick", scenes="synthetic",
               metrics={"plate_acc": float(np.mean([c for c, w in zip(correct, widths) if w >= READABLE_MIN_WIDTH_PX]))},
               units=Units("plate", "s#", tuple(str(i) for i in range(len(correct))),
                           {"correct": tuple(correct), "width_px": tuple(widths)}))


def test_plate_width_is_one_chart_per_entry_drawn_from_its_plates(tmp_path):
    board = tmp_path / "board"
    (board / "entries").mkdir(parents=True)
    widths = [16.0, 24.0, 40.0, 70.0, 90.0, 130.0]
    rows = [Row(kind="utility", attack="utility", lens="gp", seed=0, profile="quick", scenes="synthetic",
                metrics={"miou": 0.3}),
            _plates("lpdr", [0, 0, 1, 1, 1, 1], widths), _plates("wiener-known-psf>lpdr", [0, 1, 0, 1, 0, 1], widths)]
    publish(rows, get_profile("quick").to_dict(), {}, board)
    written = leaderboard_report.render(board)
    charts = sorted((board / "charts").glob(f"{board_files.PLATE_WIDTH_PREFIX}*.png"))
    assert [p.name for p in charts] == ["plate_width__gp__quick__synthetic.png"]
    assert charts[0] in written and f"(charts/{charts[0].name})" in (board / board_files.CHARTS_PAGE).read_text()
    records = board_files.plate_records(load_entries(board)[0])
    assert len(records) == 12 and sum(r["correct"] for r in records) == 7
