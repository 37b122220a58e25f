"""Regression tests on the published numbers (RobustBench's pattern).

- fast, always: the smoke profile of `ideal` and `defocus` (seed 0, the cheap attackers) reproduces
  the published smoke entries within tolerances derived from the measured seed spread;
- exact, RUN_SLOW=1: re-runs the quick profile of a published entry and checks every metric.

That the leaderboard's pages and charts regenerate identically from the entries is checked in
tests/leaderboard/test_board_files.py.
"""

import os
import subprocess
import sys
from pathlib import Path

import pytest

from benchmark.results import entries as leaderboard
from benchmark.results.entries import Entry
from benchmark.results.schema import Row, read_results

pytestmark = pytest.mark.slow  # regression re-checks: published figures re-run in subprocesses

ENTRIES = leaderboard.LEADERBOARD / "entries"
# Timing and throughput depend on the machine and its load, not on the code's numbers.
SKIP = {"fit_s", "images_per_s", "wall_s", "threads"}
SKIP_SUFFIX = "_s_per_image"  # a reader's seconds per stage
# Cheap attackers of the standard ensemble, which the entries are published with: the rerun names them
# (the cross product among them), and only the chains the entry holds are compared.
FAST_ATTACKS = ("nafnet-known-psf", "lpdr", "learned-reader", "learned-reader-psf")


def tolerance(stats: leaderboard.Stat) -> float:
    """4 seed standard deviations, floored for metrics whose seeds happen to agree."""
    return max(4.0 * stats.std, 1e-6 + 1e-3 * abs(stats.mean))


def rerun(tmp_path: Path, profile: str, lenses: list[str], attacks: list[str], seed: int) -> list[Row]:
    cmd = [sys.executable, "-m", "benchmark", "run", "--profile", profile, "--seeds", str(seed), "--out",
           str(tmp_path / "run")]
    for lens in lenses:
        cmd += ["--lens", lens]
    for attack in attacks:
        cmd += ["--attack", attack]
    proc = subprocess.run(cmd, capture_output=True, text=True, timeout=3600,
                          env={**os.environ, "PLB_CACHE": str(tmp_path / "cache")})
    assert proc.returncode == 0, proc.stderr[-3000:]
    return read_results(tmp_path / "run" / "results.json").rows


def compare(entry: Entry, rows: list[Row], seed: int, attacks: set[str] | None) -> int:
    """Assert every re-measured metric of `rows` matches the entry's value for `seed`; return the count."""
    checked = 0
    for row in rows:
        if not row.ok or row.lens != entry.lens or (attacks is not None and row.attack.split(">")[0] not in attacks
                                                    and row.kind not in ("lens", "utility", "bound")):
            continue
        stored = entry.chain(row.attack)
        if stored is None and ">" in row.attack:  # a chain of the cross product outside the standard ensemble
            continue
        assert stored is not None, f"{entry.lens}: the entry has no {row.attack!r}"
        index = stored.seeds.index(seed)
        for name, stats in stored.metrics.items():
            if name in SKIP or name.endswith(SKIP_SUFFIX) or name not in row.metrics:
                continue
            expected = stats.values[index]
            if expected is None:
                continue
            assert row.metrics[name] == pytest.approx(expected, abs=tolerance(stats)), (entry.lens, row.attack, name)
            checked += 1
    return checked


def test_smoke_profile_reproduces_the_published_figures(tmp_path):
    entries = {e.lens: e for e in leaderboard.load_entries() if e.profile == "smoke"}
    assert {"ideal", "defocus", "sharp"} <= set(entries), "publish smoke entries: see leaderboard/README.md"
    rows = rerun(tmp_path, "smoke", ["ideal", "defocus"], list(FAST_ATTACKS), seed=0)
    checked = sum(compare(entries[lens], rows, 0, set(FAST_ATTACKS)) for lens in ("ideal", "defocus", "sharp"))
    assert checked > 50


@pytest.mark.skipif(not os.environ.get("RUN_SLOW"), reason="re-runs the quick profile (minutes); set RUN_SLOW=1")
@pytest.mark.parametrize("lens", [os.environ.get("RUN_SLOW_LENS", "defocus")])
def test_quick_profile_entry_reproduces_exactly(tmp_path, lens):
    entry = next(e for e in leaderboard.load_entries() if e.lens == lens and e.profile == "quick")
    attacks = sorted({c.attack.split(">")[0] for c in entry.chains() if c.kind not in ("lens", "utility", "bound")})
    seed = entry.seeds[0]
    rows = rerun(tmp_path, "quick", [lens], attacks, seed)
    assert compare(entry, rows, seed, None) > 20
