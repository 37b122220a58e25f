"""The findings table decides each claim by a paired comparison of per-unit outcomes (benchmark.publish.findings)."""

import numpy as np
import pytest
from scipy import stats as sps

from benchmark.publish import findings
from benchmark.results import stats
from benchmark.results.entries import make_entry
from benchmark.publish.tables import findings_lines, findings_table
from benchmark.results.schema import Row, Units

PROFILE = "quick"


def _scene_names(seed: int, n: int) -> list[str]:
    return [f"synthetic/val/{seed}/{i:05d}" for i in range(n)]


def _restorer(lens: str, attack: str, seed: int, psnr: np.ndarray, units: bool = True) -> Row:
    row = Row(kind="restorer", lens=lens, attack=attack, restorer=attack, seed=seed, profile=PROFILE,
              scenes="synthetic", metrics={"psnr_db": float(np.mean(psnr))})
    if units:
        row.set_units(Units.from_names("scene", _scene_names(seed, len(psnr)), {"psnr_db": psnr.tolist()}))
    return row


def _utility(lens: str, seed: int, inter: np.ndarray, union: np.ndarray) -> Row:
    present = union.sum(0) > 0
    miou = float((inter.sum(0)[present] / union.sum(0)[present]).mean())
    row = Row(kind="utility", lens=lens, attack="utility", seed=seed, profile=PROFILE, scenes="synthetic",
              metrics={"miou": miou})
    row.set_units(Units.from_names("scene", _scene_names(seed, len(inter)),
                                   {"intersection": inter.tolist(), "union": union.tolist()}))
    return row


def _reader(lens: str, seed: int, correct: np.ndarray) -> Row:
    names = [f"synthetic/val/{seed}/{i // 2:05d}@x0y0p{i % 2}#0" for i in range(len(correct))]
    row = Row(kind="reader", lens=lens, attack="lpdr", reader="lpdr", seed=seed, profile=PROFILE, scenes="synthetic",
              metrics={"plate_acc": float(np.mean(correct)), "n_plates": len(correct)})
    row.set_units(Units.from_names("plate", names, {"correct": correct.astype(int).tolist(),
                                                    "char_errors": (1 - correct).astype(int).tolist()}))
    return row


def _entry(lens: str, rows: list[Row]):
    return make_entry(lens, rows, {"name": PROFILE}, None, None)


def _psnr_entries(n_scenes: int, shift: float, seeds=(0, 1, 2)):
    """gp's restorer reaches `shift` dB less than os-d-1000's on the same scenes (which differ a lot)."""
    rng = np.random.default_rng(3)
    gp, strong = [], []
    for s in seeds:
        scenes = rng.normal(25.0, 4.0, size=n_scenes)
        gp.append(_restorer("gp", "wiener-known-psf", s, scenes - shift + rng.normal(0, 1.5, n_scenes)))
        strong.append(_restorer("os-d-1000", "wiener-known-psf", s, scenes + rng.normal(0, 1.5, n_scenes)))
    return [_entry("gp", gp), _entry("os-d-1000", strong)]


def _finding(entries, claim: str):
    return next(f for f in findings.check_findings(entries) if f.claim == claim)


PSNR_CLAIM = "GP gives lambda_deb = 1000 privacy (attacker PSNR no higher)"


def test_psnr_verdict_is_paired_and_flips_to_cannot_tell_when_the_sample_shrinks():
    big = _finding(_psnr_entries(64, 0.5), PSNR_CLAIM)
    assert big.label == stats.HOLDS
    assert big.comparison is not None and big.comparison.n == 3 * 64
    assert big.comparison.method == "paired-bootstrap" and big.comparison.high < 0
    # Unpaired, the 4 dB scene spread would give an interval about 1.7 dB wide; paired, it cancels.
    assert big.comparison.high - big.comparison.low < 1.0
    small = _finding(_psnr_entries(8, 0.5, seeds=(0,)), PSNR_CLAIM)
    assert small.label == stats.CANNOT_TELL and small.comparison is not None and small.comparison.n == 8
    assert "p = " in small.verdict and "n = 8" in small.verdict
    worse = _finding(_psnr_entries(64, -0.5), PSNR_CLAIM)
    assert worse.label == stats.DOES_NOT_HOLD


def test_psnr_is_each_scenes_best_restorer_among_those_both_lenses_met():
    rng = np.random.default_rng(0)
    scenes = rng.normal(25.0, 3.0, size=40)
    gp = [_restorer("gp", "wiener-known-psf", 0, scenes - 2.0), _restorer("gp", "nafnet", 0, scenes + 1.0)]
    strong = [_restorer("os-d-1000", "wiener-known-psf", 0, scenes), _restorer("os-d-1000", "nafnet", 0, scenes - 3.0),
              _restorer("os-d-1000", "only-here", 0, scenes + 10.0)]
    found = _finding([_entry("gp", gp), _entry("os-d-1000", strong)], PSNR_CLAIM)
    # Each scene at its best restorer: gp's is nafnet's (scenes + 1), os-d-1000's wiener's (scenes);
    # "only-here" never ran on gp, so it stays out of both ensembles.
    assert (found.attack_a, found.attack_b) == ("per-scene best of 2 restorers",) * 2
    assert found.comparison is not None and found.comparison.difference == pytest.approx(1.0, abs=1e-3)
    assert found.label == stats.DOES_NOT_HOLD


def test_miou_is_recomputed_from_per_scene_counts():
    rng = np.random.default_rng(1)
    union = rng.integers(0, 5000, size=(32, 19))
    union[:, 7] = 0  # a class absent from every scene is left out of the mean
    gp_inter = (union * rng.uniform(0.3, 0.6, size=union.shape)).astype(int)
    os_inter = (union * rng.uniform(0.1, 0.4, size=union.shape)).astype(int)
    entries = [_entry("gp", [_utility("gp", 0, gp_inter, union)]),
               _entry("os-d-1000", [_utility("os-d-1000", 0, os_inter, union)])]
    found = _finding(entries, "GP keeps more utility than lambda_deb = 1000")
    expected = entries[0].metric("utility", "miou").mean - entries[1].metric("utility", "miou").mean
    assert found.comparison is not None and found.comparison.difference == pytest.approx(expected, abs=1e-12)
    assert found.label == stats.HOLDS
    # The statistic on one stratum is the pooled mIoU itself.
    stacked = np.stack([gp_inter, union], axis=1)
    assert findings._miou([stacked]) == pytest.approx(entries[0].metric("utility", "miou").mean, abs=1e-12)


def test_plate_reads_are_decided_by_mcnemar_on_the_same_plates():
    # 60 plates: both read 20, only gp 4, only os 16, neither 20 -> gp reads fewer.
    gp = np.array([1] * 20 + [1] * 4 + [0] * 16 + [0] * 20)
    os = np.array([1] * 20 + [0] * 4 + [1] * 16 + [0] * 20)
    entries = [_entry("gp", [_reader("gp", 0, gp)]), _entry("os", [_reader("os", 0, os)])]
    found = _finding(entries, "GP lowers the readers' ensemble plate accuracy against OS")
    assert found.comparison is not None and found.comparison.n == 60
    assert found.comparison.p_value == pytest.approx(sps.binomtest(4, 20, 0.5).pvalue)
    assert found.comparison.difference == pytest.approx((4 - 16) / 60)
    assert found.label == stats.HOLDS
    # A quarter of the plates, the same rates: too few discordant plates to tell.
    quarter = np.r_[0:5, 20:21, 24:28, 40:45]
    entries = [_entry("gp", [_reader("gp", 0, gp[quarter])]), _entry("os", [_reader("os", 0, os[quarter])])]
    assert _finding(entries, "GP lowers the readers' ensemble plate accuracy against OS").label == stats.CANNOT_TELL


def test_plates_pair_by_id_not_by_position():
    gp = np.array([1, 0, 1, 0, 1, 0, 1, 0])
    a, b = _reader("gp", 0, gp), _reader("os", 0, gp)
    # The same outcomes listed in another order on one side: every plate agrees.
    order = [7, 6, 5, 4, 3, 2, 1, 0]
    names = b.units.names()
    b.set_units(Units.from_names("plate", [names[i] for i in order],
                                 {k: [v[i] for i in order] for k, v in b.units.values.items()}))
    found = _finding([_entry("gp", [a]), _entry("os", [b])], "GP lowers the readers' ensemble plate accuracy against OS")
    assert found.comparison is not None and found.comparison.difference == 0.0 and found.comparison.p_value == 1.0


def test_entries_without_units_say_so_and_never_pair():
    rng = np.random.default_rng(0)
    old = _entry("gp", [_restorer("gp", "wiener-known-psf", 0, rng.normal(20, 1, 8), units=False)])
    new = _entry("os-d-1000", [_restorer("os-d-1000", "wiener-known-psf", 0, rng.normal(30, 1, 8))])
    found = _finding([old, new], PSNR_CLAIM)
    assert found.comparison is None and found.label == stats.CANNOT_TELL
    assert found.verdict == findings.NO_UNITS
    line = next(x for x in findings_lines([old, new]) if x[1] == PSNR_CLAIM)
    assert line[-1] == "cannot tell: entry has no per-unit outcomes (re-publish)" and line[6] == ""


def test_different_scenes_are_not_paired():
    rng = np.random.default_rng(0)
    a = _restorer("gp", "wiener-known-psf", 0, rng.normal(20, 1, 8))
    b = _restorer("os-d-1000", "wiener-known-psf", 0, rng.normal(30, 1, 8))
    b.set_units(Units.from_names("scene", [f"photos/val/0/{i:05d}" for i in range(8)], b.units.values))
    found = _finding([_entry("gp", [a]), _entry("os-d-1000", [b])], PSNR_CLAIM)
    assert found.comparison is None and "share no scene or plate id" in found.verdict


def test_missing_lenses_are_skipped():
    assert findings_table(_psnr_entries(4, 0.0)[:1]) == ""
    claims = {f.claim for f in findings.check_findings(_psnr_entries(4, 0.0))}
    assert claims == {PSNR_CLAIM}  # no utility or reader rows: only the PSNR claim applies


def _noted(rows: list[Row], version: str | None) -> list[Row]:
    for row in rows:
        if version is not None:
            row.notes["trainer_version"] = version
    return rows


def _lens_row(lens: str, seed: int) -> Row:
    return Row(kind="lens", lens=lens, attack="lens", seed=seed, profile=PROFILE, scenes="synthetic", metrics={})


@pytest.mark.slow
def test_entries_of_different_trainer_versions_are_not_compared():
    rng = np.random.default_rng(1)
    union = rng.integers(0, 5000, size=(32, 19))
    inter = (union * rng.uniform(0.3, 0.6, size=union.shape)).astype(int)
    weak = (union * rng.uniform(0.1, 0.4, size=union.shape)).astype(int)
    scenes = rng.normal(25.0, 4.0, size=64)

    def entries(va, vb):
        gp = _noted([_utility("gp", 0, inter, union), _lens_row("gp", 0),
                     _restorer("gp", "wiener-known-psf", 0, scenes - 0.5)], va)
        od = _noted([_utility("os-d-1000", 0, weak, union), _lens_row("os-d-1000", 0),
                     _restorer("os-d-1000", "wiener-known-psf", 0, scenes)], vb)
        return [_entry("gp", gp), _entry("os-d-1000", od)]

    utility = "GP keeps more utility than lambda_deb = 1000"
    for claim in (utility, PSNR_CLAIM):
        assert _finding(entries("4", "4"), claim).label == stats.HOLDS
        assert _finding(entries(None, None), claim).label == stats.HOLDS
        mixed = _finding(entries("4", None), claim)
        assert mixed.comparison is None and mixed.label == stats.CANNOT_TELL
        assert "different co-design trainer versions (4 against not noted" in mixed.verdict


def test_a_fixed_lens_privacy_does_not_depend_on_the_trainer_version():
    scenes = np.random.default_rng(2).normal(25.0, 4.0, size=64)
    defocus = _noted([_lens_row("defocus", 0), _restorer("defocus", "wiener-known-psf", 0, scenes - 0.5)], "4")
    ideal = [_lens_row("ideal", 0), _restorer("ideal", "wiener-known-psf", 0, scenes)]
    found = _finding([_entry("defocus", defocus), _entry("ideal", ideal)],
                     "defocus lowers the attacker's PSNR against the ideal lens")
    assert found.comparison is not None and found.label == stats.HOLDS
