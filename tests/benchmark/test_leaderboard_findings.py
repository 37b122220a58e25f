"""The paper's findings table is computed from the entries: its verdicts follow the numbers."""

from benchmark.leaderboard_report import findings_table


def _entry(lens: str, miou: list[float], psnr: list[float]) -> dict:
    def stats(values):
        mean = sum(values) / len(values)
        std = (sum((v - mean) ** 2 for v in values) / (len(values) - 1)) ** 0.5 if len(values) > 1 else 0.0
        return {"mean": mean, "std": std, "values": values}
    return {"lens": lens, "profile": "quick", "seeds": list(range(len(miou))), "rows": [
        {"attack": "utility", "metrics": {"miou": stats(miou)}},
        {"attack": "wiener-known-psf", "metrics": {"psnr_db": stats(psnr)}}]}


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
    strong["rows"].append({"attack": "nafnet-known-pairs", "metrics": {"psnr_db": {"mean": 35.0, "std": 0.0}}})
    verdicts = _verdicts([_entry("gp", [0.3], [21.0]), strong])
    assert verdicts["GP gives lambda_deb = 1000 privacy (attacker PSNR no higher)"] == "holds (one seed: no spread)"
