"""`report --publish RUN_DIR` publishes a finished run from its results.json exactly as `run --publish`
would have (the same entry file), and refuses a file that is not a run's own results."""

from __future__ import annotations

import json

import pytest

import benchmark
from benchmark.publish import leaderboard
from benchmark.store.profiles import get_profile
from benchmark.results.schema import Results, write_results


@pytest.mark.slow
def test_publishing_a_finished_run_gives_the_entry_run_publish_gives(tmp_path):
    out = tmp_path / "run"
    results = benchmark.run(["defocus"], ["identity", "lpdr-oracle"], profile="smoke", out=out)
    output = results.output
    live, later = tmp_path / "live", tmp_path / "later"
    (live / "entries").mkdir(parents=True)
    (later / "entries").mkdir(parents=True)
    expected = leaderboard.publish_run(output.rows, get_profile("smoke").to_dict(), output.lens_info, out, live,
                                       output.settings)
    got = leaderboard.publish_results(out, later)
    assert sorted(p.name for p in got) == sorted(p.name for p in expected) == ["defocus__smoke__synthetic.json",
                                                                             "sharp__smoke__synthetic.json"]
    for path in expected:
        assert json.loads((later / "entries" / path.name).read_text()) == json.loads(path.read_text())
    assert (later / "README.md").read_text() == (live / "README.md").read_text()


def test_a_results_file_without_a_profile_is_refused(tmp_path):
    write_results(tmp_path / "results.json", Results(rows=[]))
    with pytest.raises(ValueError, match="no profile in its meta"):
        leaderboard.publish_results(tmp_path, tmp_path / "board")
