"""The trade-off table names a worst-case attacker that ran on fewer seeds than its entry
(NAFNet attackers fitted at seed 0 only) with the seeds it ran on."""

from benchmark.results.entries import make_entry
from benchmark.publish.tables import main_table
from benchmark.results.schema import Row

PROFILE = {"name": "quick", "n_val": 64, "image_size": (512, 1024)}


def _row(attack: str, seed: int, psnr: float) -> Row:
    return Row(kind="restorer", lens="gp", attack=attack, restorer=attack, seed=seed, profile="quick",
               scenes="synthetic", metrics={"psnr_db": psnr}, settings_hash="h", provenance={"date": "d"})


def _worst_cell(rows: list[Row]) -> str:
    table = main_table([make_entry("gp", rows, PROFILE, None, None, {})])
    head, _, line = table.splitlines()[:3]
    columns = [c.strip() for c in head.strip("|").split("|")]
    return [c.strip() for c in line.strip("|").split("|")][columns.index("worst PSNR dB [95 %] (attacker)")]


def test_a_worst_case_on_fewer_seeds_says_which():
    rows = [_row("wiener-known-psf", s, 25.0 + s) for s in (0, 1, 2)] + [_row("nafnet-known-pairs", 0, 30.0)]
    assert _worst_cell(rows) == "30.00 (no per-scene outcomes) (nafnet-known-pairs, seed 0 only)"


def test_a_worst_case_on_every_seed_is_plain():
    rows = [_row("wiener-known-psf", s, 25.0 + s) for s in (0, 1, 2)] + [_row("nafnet-known-pairs", 0, 20.0)]
    # Rows without per-scene outcomes: the mean over seeds, saying so instead of an interval.
    assert _worst_cell(rows) == "26.00 (no per-scene outcomes) (wiener-known-psf)"


def test_the_strongest_is_chosen_on_the_seeds_both_ran():
    # wiener beat nafnet at seed 0 (28 > 27), the only seed nafnet ran; its three-seed mean (25.33)
    # is lower than nafnet's one value, which must not make nafnet the worst case.
    rows = [_row("wiener-known-psf", s, v) for s, v in ((0, 28.0), (1, 24.0), (2, 24.0))]
    rows.append(_row("nafnet-known-pairs", 0, 27.0))
    assert _worst_cell(rows) == "25.33 (no per-scene outcomes) (wiener-known-psf)"


def test_with_no_shared_seed_the_highest_mean_is_the_worst_case():
    rows = [_row("wiener-known-psf", 1, 25.0), _row("nafnet-known-pairs", 0, 27.0)]
    assert _worst_cell(rows).startswith("27.00 (no per-scene outcomes) (nafnet-known-pairs")
