"""The paper's findings table is computed from the entries: its verdicts follow the numbers."""

from benchmark.leaderboard_entries import make_entry
from benchmark.leaderboard_tables import findings_table
from benchmark.schema import Row


def _row(lens: str, kind: str, attack: str, seed: int, metrics: dict) -> Row:
    return Row(kind=kind, lens=lens, attack=attack, restorer=None if kind == "utility" else attack, seed=seed,
               profile="quick", scenes="synthetic", metrics=metrics)


def _entry(lens: str, miou: list[float], psnr: list[float]):
    rows = [_row(lens, "utility", "utility", s, {"miou": v}) for s, v in enumerate(miou)]
    rows += [_row(lens, "restorer", "wiener-known-psf", s, {"psnr_db": v}) for s, v in enumerate(psnr)]
    return make_entry(lens, rows, {"name": "quick"}, None, None)


def _verdicts(entries):
    rows = [line.split(" | ") for line in findings_table(entries).splitlines()[2:]]
    return {row[1]: row[-1].rstrip(" |") for row in rows}


def test_verdicts_follow_the_numbers_and_their_spread():
    verdicts = _verdicts([
        _entry("os-d-1", [0.30, 0.32, 0.31], [30.0, 30.2, 29.8]),
        _entry("os-d-1000", [0.20, 0.21, 0.19], [22.0, 22.1, 21.9]),
        _entry("gp", [0.20, 0.40, 0.30], [22.0, 22.5, 21.5]),
        _entry("os-d-mtadam", [0.3, 0.3, 0.3], [21.0, 21.1, 20.9]),
    ])
    assert verdicts["more lambda_deb costs utility"] == "holds"
    assert verdicts["more lambda_deb lowers the attacker's PSNR"] == "holds"
    assert verdicts["GP gives lambda_deb = 1000 privacy (attacker PSNR no higher)"] == "holds"
    assert verdicts["GP keeps more utility than lambda_deb = 1000"] == "within seed noise"
    assert verdicts["MTAdam gives weaker privacy than lambda_deb = 1000"] == "does not hold"


def test_single_seeds_are_flagged_and_missing_lenses_skipped():
    verdicts = _verdicts([_entry("gp", [0.3], [25.0]), _entry("os-d-1000", [0.2], [22.0])])
    assert verdicts["GP gives lambda_deb = 1000 privacy (attacker PSNR no higher)"] == "does not hold (one seed: no spread)"
    assert set(verdicts) == {"GP gives lambda_deb = 1000 privacy (attacker PSNR no higher)",
                             "GP keeps more utility than lambda_deb = 1000"}
    assert findings_table([_entry("ideal", [0.3], [25.0])]) == ""


def test_attackers_only_one_lens_met_do_not_decide():
    strong = _entry("os-d-1000", [0.2], [22.0])
    strong = make_entry("os-d-1000", strong.rows + [_row("os-d-1000", "restorer", "nafnet-known-pairs", 0,
                                                         {"psnr_db": 35.0})], {"name": "quick"}, None, None)
    verdicts = _verdicts([_entry("gp", [0.3], [21.0]), strong])
    assert verdicts["GP gives lambda_deb = 1000 privacy (attacker PSNR no higher)"] == "holds (one seed: no spread)"
