"""Publishing an entry merges with the stored one instead of erasing rows it did not measure."""

import json

import pytest

from benchmark import leaderboard

PROFILE = {"name": "smoke", "n_val": 4, "image_size": (128, 256)}  # a tuple, as Profile.to_dict() gives


def _rows(attacks: list[str], commit: str, value: float = 1.0, seeds: tuple[int, ...] = (0,)) -> list[dict]:
    return [{"lens": "sharp", "attack": a, "seed": s, "profile": "smoke", "scenes": "synthetic",
             "config_hash": f"{a}-{commit}", "git_commit": commit, "date": "d", "psnr": value + s}
            for a in attacks for s in seeds]


def test_fewer_attackers_keep_the_richer_rows_with_their_provenance(tmp_path):
    (path,) = leaderboard.publish(_rows(["identity", "lpdr-oracle"], "aaa"), PROFILE, {}, tmp_path)
    leaderboard.publish(_rows(["identity"], "bbb", value=2.0), PROFILE, {}, tmp_path)
    entry = json.loads(path.read_text())
    rows = {r["attack"]: r for r in entry["rows"]}
    assert set(rows) == {"identity", "lpdr-oracle"}
    assert rows["identity"]["metrics"]["psnr"]["mean"] == 2.0 and "provenance" not in rows["identity"]
    assert rows["lpdr-oracle"]["provenance"]["git_commit"] == "aaa"
    assert entry["provenance"]["git_commit"] == "bbb"
    assert entry["config_hashes"] == ["identity-aaa", "identity-bbb", "lpdr-oracle-aaa"]


def test_a_different_measurement_replaces_the_entry(tmp_path):
    (path,) = leaderboard.publish(_rows(["identity", "lpdr-oracle"], "aaa"), PROFILE, {}, tmp_path)
    leaderboard.publish(_rows(["identity"], "bbb"), {**PROFILE, "n_val": 8}, {}, tmp_path)
    assert [r["attack"] for r in json.loads(path.read_text())["rows"]] == ["identity"]


def test_more_seeds_for_some_attackers_keep_the_others_with_their_seeds(tmp_path):
    (path,) = leaderboard.publish(_rows(["identity", "nafnet"], "aaa"), PROFILE, {}, tmp_path)
    leaderboard.publish(_rows(["identity"], "bbb", seeds=(0, 1, 2)), PROFILE, {}, tmp_path)
    entry = json.loads(path.read_text())
    rows = {r["attack"]: r for r in entry["rows"]}
    assert entry["seeds"] == [0, 1, 2]
    assert rows["identity"]["seeds"] == [0, 1, 2] and rows["identity"]["metrics"]["psnr"]["std"] == 1.0
    assert rows["nafnet"]["seeds"] == [0] and rows["nafnet"]["provenance"]["git_commit"] == "aaa"


def test_seeds_with_nothing_to_score_leave_mean_and_std_finite():
    rows = [{"lens": "x", "attack": "lpdr", "seed": s, "plate_acc": v} for s, v in enumerate([0.5, float("nan"), 0.25])]
    (row,) = leaderboard.aggregate(rows)
    stats = row["metrics"]["plate_acc"]
    assert stats["mean"] == 0.375 and stats["std"] == pytest.approx(0.1767767, rel=1e-6)
    assert stats["values"] == [0.5, None, 0.25]
    (row,) = leaderboard.aggregate(rows[:2])
    assert row["metrics"]["plate_acc"]["std"] == 0.0
