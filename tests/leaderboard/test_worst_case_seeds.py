"""The trade-off table names a worst-case attacker that ran on fewer seeds than its entry
(NAFNet attackers fitted at seed 0 only) with the seeds it ran on."""

from benchmark.leaderboard_entries import make_entry
from benchmark.leaderboard_tables import main_table
from benchmark.schema import Row

PROFILE = {"name": "quick", "n_val": 64, "image_size": (512, 1024)}


def _row(attack: str, seed: int, psnr: float) -> Row:
    return Row(kind="restorer", lens="gp", attack=attack, restorer=attack, seed=seed, profile="quick",
               scenes="synthetic", metrics={"psnr_db": psnr}, settings_hash="h", provenance={"date": "d"})


def _worst_cell(rows: list[Row]) -> str:
    table = main_table([make_entry("gp", rows, PROFILE, None, None, {})])
    head, _, line = table.splitlines()[:3]
    columns = [c.strip() for c in head.strip("|").split("|")]
    return [c.strip() for c in line.strip("|").split("|")][columns.index("worst PSNR dB (attacker)")]


def test_a_worst_case_on_fewer_seeds_says_which():
    rows = [_row("wiener-known-psf", s, 25.0 + s) for s in (0, 1, 2)] + [_row("nafnet-known-pairs", 0, 30.0)]
    assert _worst_cell(rows) == "30.00 (nafnet-known-pairs, seed 0 only)"


def test_a_worst_case_on_every_seed_is_plain():
    rows = [_row("wiener-known-psf", s, 25.0 + s) for s in (0, 1, 2)] + [_row("nafnet-known-pairs", 0, 20.0)]
    assert _worst_cell(rows) == "26.00 ± 1.00 (wiener-known-psf)"
