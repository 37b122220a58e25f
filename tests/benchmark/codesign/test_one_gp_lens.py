"""The gp lens the package ships (what `run --lens gp` loads at seed 0), the leaderboard's gp entry and the
ideal-observer study's gp ceiling are one lens: a run of the main job reproduces its leaderboard row, and the
gap column beside it is computed for that very lens."""

from __future__ import annotations

import json
import tomllib

from benchmark.codesign.shipped import SHIPPED_DIR
from benchmark.publish.ship_lens import codesign_run
from benchmark.results.entries import LEADERBOARD
from benchmark.results.observer import published
from benchmark.store.profiles import PROFILES


def shipped_gp_spec() -> dict:
    """The spec of the shipped folder a quick gp run at seed 0 loads (the folder named by its run key)."""
    folder = SHIPPED_DIR / codesign_run("gp", PROFILES["quick"], 0).directory.name
    return tomllib.loads((folder / "lens.toml").read_text(encoding="utf-8"))


def test_the_shipped_gp_is_the_published_gp_and_the_ceiling_studys():
    shipped = shipped_gp_spec()
    entry = json.loads((LEADERBOARD / "entries" / "gp__quick__synthetic.json").read_text(encoding="utf-8"))
    study = json.loads((LEADERBOARD / "studies" / "ideal_observer.json").read_text(encoding="utf-8"))
    assert published.same_lens(shipped, entry["lens_spec"]), published.spec_differences(shipped, entry["lens_spec"])
    assert published.same_lens(shipped, study["lenses"]["gp"]["lens_spec"]), \
        published.spec_differences(shipped, study["lenses"]["gp"]["lens_spec"])
