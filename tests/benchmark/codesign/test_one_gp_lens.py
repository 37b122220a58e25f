"""The gp lens the package ships (what `run --lens gp` loads at seed 0), the leaderboard's gp entry and the
ideal-observer study's gp ceiling are one lens: a run of the main job reproduces its leaderboard row, and the
gap column beside it is computed for that very lens."""

from __future__ import annotations

import json
import tomllib
from pathlib import Path

from benchmark.results.observer import published

REPO = Path(__file__).resolve().parents[3]


def shipped_gp_spec() -> dict:
    folders = sorted((REPO / "benchmark" / "codesign" / "shipped").glob("gp-*"))
    assert len(folders) == 1, f"expected one shipped gp lens, found {[f.name for f in folders]}"
    return tomllib.loads((folders[0] / "lens.toml").read_text(encoding="utf-8"))


def test_the_shipped_gp_is_the_published_gp_and_the_ceiling_studys():
    shipped = shipped_gp_spec()
    entry = json.loads((REPO / "leaderboard" / "entries" / "gp__quick__synthetic.json").read_text(encoding="utf-8"))
    study = json.loads((REPO / "leaderboard" / "studies" / "ideal_observer.json").read_text(encoding="utf-8"))
    assert published.same_lens(shipped, entry["lens_spec"]), published.spec_differences(shipped, entry["lens_spec"])
    assert published.same_lens(shipped, study["lenses"]["gp"]["lens_spec"]), \
        published.spec_differences(shipped, study["lenses"]["gp"]["lens_spec"])
