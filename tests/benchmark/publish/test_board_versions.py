"""One version per board (benchmark.publish.versions): entries of another code version, torch version or plate
definition are shown apart and enter no takeaway, Pareto front or chart; the code version stamped after the
fact is the digest of the row's commit; the charts plot the tables' figures."""

from __future__ import annotations

import re
import subprocess
from pathlib import Path

import pytest

from benchmark.publish import report
from benchmark.publish.leaderboard import publish
from benchmark.publish.tables import ENSEMBLE_PLATES, ENSEMBLE_PSNR, MAIN_COLUMNS, takeaways
from benchmark.publish.versions import board_split, stamp_code_versions
from benchmark.results.charts.tradeoff import tradeoff_points
from benchmark.results.entries import LEADERBOARD, display_order, load_entries, make_entry
from benchmark.results.schema import Row, Units
from benchmark.store.profiles import get_profile
from benchmark.store.provenance import code_digest

PLATES = {"readable_from": 24, "scored_from": 8}


def _names(lens: str, text: str) -> bool:
    """`text` names `lens` as a whole name (os-d-100 is not named by "os-d-1000")."""
    return re.search(rf"(?<![\w-]){re.escape(lens)}(?![\w-])", text) is not None


def _rows(lens: str, miou: float, read: int, code: str, date: str, torch: str = "2.14.1", seed: int = 0) -> list[Row]:
    """A utility row and a reader row (40 plates of 32 px, `read` of them read) stamped with `code` and `date`."""
    prov = {"code_version": code, "date": date, "packages": f"torch={torch};numpy=2.0", "git_commit": "abc"}
    common = {"lens": lens, "seed": seed, "profile": "quick", "scenes": "synthetic", "provenance": prov}
    scenes = [f"s{i}" for i in range(8)]
    utility = Units("scene", f"synthetic/val/{seed}/", tuple(scenes),
                    {"intersection": tuple((round(100 * miou), 50) for _ in scenes),
                     "union": tuple((100, 100) for _ in scenes)})
    plates = Units("plate", f"synthetic/val/{seed}/", tuple(f"s{i // 5}#{i % 5}" for i in range(40)),
                   {"correct": tuple(int(i < read) for i in range(40)), "char_errors": tuple(0 for _ in range(40)),
                    "width_px": tuple(32.0 for _ in range(40))})
    return [Row(kind="utility", attack="utility", metrics={"miou": miou}, units=utility, settings_hash="h", **common),
            Row(kind="reader", attack="lpdr", reader="lpdr", threat_model="sensor-access", settings_hash="h",
                metrics={"plate_acc": read / 40}, units=plates, **common)]


def _board(tmp_path: Path, rows: list[Row]) -> Path:
    board = tmp_path / "board"
    (board / "entries").mkdir(parents=True)
    publish(rows, get_profile("quick").to_dict(), {}, board, settings={"h": {"plates_px": PLATES}})
    return board


def test_an_entry_of_another_version_is_shown_apart_and_enters_no_takeaway_front_or_chart(tmp_path):
    # "old" reads no plate at a higher utility: mixed in, it would be the takeaway's lens and lead the front.
    rows = (_rows("new-a", 0.30, 20, "v2", "2026-12-05T10:00:00+00:00")
            + _rows("new-b", 0.25, 4, "v2", "2026-12-05T11:00:00+00:00")
            + _rows("old", 0.40, 0, "v1", "2026-11-24T10:00:00+00:00", torch="2.15.0"))
    board = _board(tmp_path, rows)
    split = board_split(display_order(load_entries(board)))
    assert [e.lens for e in split.current] == ["new-a", "new-b"] and split.versions["quick"].code == "v2"
    (apart,) = split.apart
    assert apart.entry.lens == "old" and "code SHA-256 v1" in apart.reason and "torch 2.15.0" in apart.reason
    report.render(board)
    text = (board / "README.md").read_text()
    takeaway = next(line for line in text.splitlines() if line.startswith("**Takeaway (quick).**"))
    assert not _names("old", takeaway) and _names("new-b", takeaway)
    assert "## Shown apart" in text and "- **old** (quick): code SHA-256 v1" in text
    assert [p.lens for p in tradeoff_points(split.current, "plate_acc", 100.0)] == ["new-a", "new-b"]
    page = (board / "index.html").read_text()
    assert 'data-lens="old"' not in page and "Shown apart" in page
    # The injected fault: mixing the old entry in changes the takeaway, which is why it is kept out.
    assert _names("old", takeaways(split.current + [apart.entry])["quick"])


def test_an_entry_mixing_two_versions_is_apart_even_if_its_newest_rows_are_the_boards(tmp_path):
    rows = (_rows("a", 0.30, 20, "v2", "2026-12-05T10:00:00+00:00")
            + _rows("b", 0.30, 20, "v2", "2026-12-05T10:00:00+00:00")
            + _rows("b", 0.30, 20, "v1", "2026-11-24T10:00:00+00:00", seed=1))
    split = board_split(load_entries(_board(tmp_path, rows)))
    assert [e.lens for e in split.current] == ["a"]
    assert split.apart[0].entry.lens == "b" and split.apart[0].reason.startswith("2 versions in one entry")


def test_the_plate_definition_is_part_of_the_version(tmp_path):
    rows = _rows("a", 0.30, 20, "v2", "2026-12-05T10:00:00+00:00")
    board = _board(tmp_path, rows)
    legacy = _rows("b", 0.30, 20, "v2", "2026-12-04T10:00:00+00:00")
    publish(legacy, get_profile("quick").to_dict(), {}, board, settings={"h": {}})  # no plates_px: from 32 px
    split = board_split(load_entries(board))
    assert [e.lens for e in split.current] == ["a"] and "plates every plate from 32 px" in split.apart[0].reason


def _git(repo: Path, *args: str) -> str:
    return subprocess.run(["git", *args], cwd=repo, check=True, capture_output=True, text=True).stdout.strip()


@pytest.mark.slow  # runs git
def test_a_stamped_code_version_is_the_digest_of_the_rows_commit(tmp_path):
    repo = tmp_path / "repo"
    for package in ("lenses", "attacks", "benchmark"):
        (repo / package).mkdir(parents=True)
        (repo / package / "x.py").write_text("A = 1\n")
    _git(repo, "init", "-q")
    _git(repo, "-c", "user.email=t@t", "-c", "user.name=t", "add", ".")
    _git(repo, "-c", "user.email=t@t", "-c", "user.name=t", "commit", "-qm", "one")
    first = _git(repo, "rev-parse", "HEAD")
    (repo / "benchmark" / "x.py").write_text('"""Docs only."""\nA = 1\n')
    _git(repo, "-c", "user.email=t@t", "-c", "user.name=t", "commit", "-qam", "docs")
    docs = _git(repo, "rev-parse", "HEAD")
    (repo / "benchmark" / "x.py").write_text("A = 2\n")
    _git(repo, "-c", "user.email=t@t", "-c", "user.name=t", "commit", "-qam", "code")
    code = _git(repo, "rev-parse", "HEAD")
    rows = []
    for commit in (first, docs, code, first + "-dirty"):
        row = _rows("a", 0.3, 1, "", "2026-12-05")[0]
        row.provenance.update(git_commit=commit)
        del row.provenance["code_version"]
        rows.append(row)
    entry = make_entry("a", rows, get_profile("quick").to_dict(), None, None)
    assert stamp_code_versions(entry, repo) == 3  # the dirty commit's code is unknown: left unstamped
    stamped = [r.provenance.get("code_version") for r in entry.rows]
    assert stamped[0] == stamped[1] != stamped[2] and stamped[3] is None
    assert stamped[2] == code_digest(repo, packages="torch=2.14.1;numpy=2.0")  # the tree at HEAD is `code`'s


def _cell(header: str):
    return next(c for c in MAIN_COLUMNS if c.header == header).cell


@pytest.mark.parametrize("privacy, scale, header", [("plate_acc", 100.0, ENSEMBLE_PLATES),
                                                    ("psnr_db", 1.0, ENSEMBLE_PSNR)])
def test_the_published_charts_plot_the_tables_figures(privacy, scale, header):
    entries = board_split(display_order(load_entries())).current
    points = {(p.lens, p.profile): p for p in tradeoff_points(entries, privacy, scale)}
    assert points
    for e in entries:
        value = _cell(header)(e, None)[1]
        if value is None:
            assert (e.lens, e.profile) not in points
        else:
            assert points[e.lens, e.profile].privacy == pytest.approx(value)


def test_the_published_page_charts_and_takeaways_hold_only_the_boards_version():
    split = board_split(display_order(load_entries()))
    page = (LEADERBOARD / "index.html").read_text()
    charted = set(re.findall(r'class="point"[^>]*data-lens="([^"]+)"', page))
    assert charted <= {e.lens for e in split.current}
    for apart in split.apart:
        assert not _names(apart.entry.lens, takeaways(split.current).get(apart.entry.profile, ""))
