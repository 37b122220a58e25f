"""Publishing a lens given as a spec path (`--lens lenses/specs/defocus.toml ... --publish`) writes its
entry, copies its pictures under file-safe names and re-renders the pages (the
width chart's name was once built from the raw path, so rendering never happened)."""

from __future__ import annotations

import os
import stat

import numpy as np
import pytest
from PIL import Image

from benchmark.publish import leaderboard
from benchmark.results.entries import file_safe, load_entries
from benchmark.results.schema import Row
from benchmark.store.profiles import get_profile

PROFILE = get_profile("smoke").to_dict()


def _png(path) -> None:
    Image.fromarray(np.zeros((4, 4, 3), dtype=np.uint8)).save(path)


def _rows(lens: str) -> list[Row]:
    ids = {"lens": lens, "seed": 0, "profile": "smoke", "scenes": "synthetic"}
    return [Row(kind="utility", attack="utility", metrics={"miou": 0.3}, **ids),
            Row(kind="restorer", attack="identity", restorer="identity", metrics={"psnr_db": 20.0}, **ids)]


@pytest.mark.parametrize("lens", ["lenses/specs/defocus.toml", "/abs/path/my lens.toml", "odd[1]*?.toml"])
def test_a_spec_path_lens_is_published_and_rendered(tmp_path, lens):
    run, board = tmp_path / "run", tmp_path / "board"
    run.mkdir()
    # The runner's names for the pictures of a lens whose name holds "/" (benchmark.runner.pictures).
    _png(run / f"samples_{lens}_seed0.png".replace("/", "_"))
    _png(run / "plate_accuracy_vs_width.png")
    old = os.umask(0o022)
    try:
        (path,) = leaderboard.publish_run(_rows(lens), PROFILE, {lens: {}}, run, board)
    finally:
        os.umask(old)
    safe = file_safe(lens)
    assert "/" not in safe and path == board / "entries" / f"{safe}__smoke__synthetic.json"
    assert [e.lens for e in load_entries(board)] == [lens]  # the entry keeps the lens's own name
    # The run's sample grid is copied; its plate-width chart is not (one chart per entry is drawn from
    # the entry's own plate widths, benchmark.publish.board_files).
    assert sorted(p.name for p in (board / "samples").iterdir()) == [f"{safe}__smoke.png"]
    assert f"(samples/{safe}__smoke.png)" in (board / "charts.md").read_text()
    assert f"samples/{safe}__smoke.png" in (board / "index.html").read_text()
    # The page and the tables can be served by another user.
    for written in (path, board / "README.md", board / "index.html"):
        assert stat.S_IMODE(written.stat().st_mode) == 0o644, written
