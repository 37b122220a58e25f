"""Publishing an entry merges with the stored one instead of erasing rows it did not measure."""

import json

import pytest

from benchmark.publish import leaderboard
from benchmark.results import entries as leaderboard_entries
from benchmark.results.entries import Entry
from benchmark.results.schema import Row

PROFILE = {"name": "smoke", "n_val": 4, "image_size": (128, 256)}  # a tuple, as Profile.to_dict() gives


def _rows(attacks: list[str], commit: str, value: float = 1.0, seeds: tuple[int, ...] = (0,)) -> list[Row]:
    return [Row(kind="restorer", lens="sharp", attack=a, restorer=a, seed=s, profile="smoke", scenes="synthetic",
                metrics={"psnr_db": value + s}, settings_hash=f"{a}-{commit}",
                provenance={"git_commit": commit, "date": "d"}) for a in attacks for s in seeds]


def _settings(attacks: list[str], commit: str) -> dict:
    return {f"{a}-{commit}": {"attacker": a} for a in attacks}


def _load(path) -> Entry:
    return Entry.from_json(json.loads(path.read_text()))


def test_fewer_attackers_keep_the_richer_rows_with_their_provenance(tmp_path):
    (path,) = leaderboard.publish(_rows(["identity", "lpdr-oracle"], "aaa"), PROFILE, {}, tmp_path,
                                  _settings(["identity", "lpdr-oracle"], "aaa"))
    leaderboard.publish(_rows(["identity"], "bbb", value=2.0), PROFILE, {}, tmp_path, _settings(["identity"], "bbb"))
    entry = _load(path)
    assert [c.attack for c in entry.chains()] == ["identity", "lpdr-oracle"]
    assert entry.metric("identity", "psnr_db").mean == 2.0
    assert entry.chain("identity").rows[0].provenance["git_commit"] == "bbb"
    assert entry.chain("lpdr-oracle").rows[0].provenance["git_commit"] == "aaa"
    # Every stored row leads back to its settings.
    assert sorted(entry.settings) == ["identity-bbb", "lpdr-oracle-aaa"]


def test_a_different_measurement_replaces_the_entry(tmp_path):
    (path,) = leaderboard.publish(_rows(["identity", "lpdr-oracle"], "aaa"), PROFILE, {}, tmp_path)
    leaderboard.publish(_rows(["identity"], "bbb"), {**PROFILE, "n_val": 8}, {}, tmp_path)
    assert [c.attack for c in _load(path).chains()] == ["identity"]


def test_more_seeds_for_some_attackers_keep_the_others_with_their_seeds(tmp_path):
    (path,) = leaderboard.publish(_rows(["identity", "nafnet"], "aaa"), PROFILE, {}, tmp_path)
    leaderboard.publish(_rows(["identity"], "bbb", seeds=(0, 1, 2)), PROFILE, {}, tmp_path)
    entry = _load(path)
    assert entry.seeds == [0, 1, 2]
    assert entry.chain("identity").seeds == (0, 1, 2) and entry.metric("identity", "psnr_db").std == 1.0
    assert entry.chain("nafnet").seeds == (0,) and entry.chain("nafnet").rows[0].provenance["git_commit"] == "aaa"


def test_seeds_with_nothing_to_score_leave_mean_and_std_finite():
    rows = [Row(kind="reader", lens="x", attack="lpdr", reader="lpdr", seed=s, profile="smoke", scenes="synthetic",
                metrics={} if v is None else {"plate_acc": v}) for s, v in enumerate([0.5, None, 0.25])]
    entry = leaderboard_entries.make_entry("x", rows, PROFILE, None, None)
    stats = entry.metric("lpdr", "plate_acc")
    assert stats.mean == 0.375 and stats.std == pytest.approx(0.1767767, rel=1e-6)
    assert stats.values == (0.5, None, 0.25)
    assert leaderboard_entries.make_entry("x", rows[:2], PROFILE, None, None).metric("lpdr", "plate_acc").std == 0.0


def test_intervals_of_the_seeds_are_enveloped():
    rows = _rows(["identity"], "aaa", seeds=(0, 1))
    rows[0].set_interval("psnr_db", 0.5, 1.5, "bootstrap")
    rows[1].set_interval("psnr_db", 1.8, 2.4, "bootstrap")
    entry = leaderboard_entries.make_entry("sharp", rows, PROFILE, None, None)
    assert entry.metric("identity", "psnr_db").interval == (0.5, 2.4)


V1_ENTRY = {
    "entry_version": 1, "lens": "gp", "profile": "quick", "scenes": "synthetic", "seeds": [0, 1],
    "profile_values": {"name": "quick"}, "coefficients_um": [0.0, 0.1], "lens_spec": {"name": "gp"},
    "config_hashes": ["h0", "h1"],
    "provenance": {"git_commit": "new", "date": "d", "device": "cpu", "packages": "p", "python": "3", "threads": 2},
    "rows": [
        {"attack": "utility", "seeds": [0, 1], "metrics": {
            "miou": {"mean": 0.25, "std": 0.07071067811865477, "values": [0.2, 0.3]},
            "wall_s": {"mean": 2.0, "std": 0.0, "values": [2.0, 2.0]}}},
        {"attack": "bound", "seeds": [0], "assumptions": "a, b", "metrics": {
            "bound_width_eps_t1": {"mean": 40.0, "std": 0.0, "values": [40.0]}}},
        {"attack": "lpdr", "seeds": [0, 1], "threat_model": "sensor-access", "metrics": {
            "plate_acc": {"mean": 0.5, "std": 0.0, "values": [0.5, None]}},
         "provenance": {"git_commit": "old", "date": "e", "device": "cpu", "packages": "p", "python": "3",
                        "threads": 2}},
        {"attack": "wiener-known-psf>lpdr", "seeds": [0], "threat_model": "sensor-access", "metrics": {
            "plate_acc": {"mean": 0.1, "std": 0.0, "values": [0.1]}}},
    ],
}


def test_version_1_entries_migrate_without_loss(tmp_path):
    migrated = leaderboard_entries.migrate_entry(V1_ENTRY)
    entry = Entry.from_json(migrated)
    assert migrated["entry_version"] == leaderboard_entries.ENTRY_VERSION == 2
    kinds = {c.attack: c.kind for c in entry.chains()}
    # lpdr's seed 1 had no readable plate (no plate_acc) and is still a reader's row.
    assert kinds == {"utility": "utility", "bound": "bound", "lpdr": "reader", "wiener-known-psf>lpdr": "chain"}
    utility = entry.chain("utility")
    assert [r.metrics for r in utility.rows] == [{"miou": 0.2}, {"miou": 0.3}]
    assert [r.provenance["wall_s"] for r in utility.rows] == [2.0, 2.0]
    miou = entry.metric("utility", "miou")
    assert miou.mean == 0.25 and miou.std == pytest.approx(0.0707107)
    assert entry.chain("bound").notes == {"bound_assumptions": "a, b"}
    lpdr = entry.chain("lpdr")
    assert lpdr.seeds == (0, 1) and lpdr.metrics["plate_acc"].values == (0.5, None)
    assert lpdr.rows[0].provenance["git_commit"] == "old" and utility.rows[0].provenance["git_commit"] == "new"
    chain = entry.chain("wiener-known-psf>lpdr").rows[0]
    assert (chain.restorer, chain.reader, chain.threat_model) == ("wiener-known-psf", "lpdr", "sensor-access")
    # Loading a version-1 file migrates it; migrate_directory rewrites it once, in the new format.
    (tmp_path / "entries").mkdir()
    path = tmp_path / "entries" / "gp__quick__synthetic.json"
    path.write_text(json.dumps(V1_ENTRY))
    assert leaderboard_entries.load_entries(tmp_path)[0].to_json() == entry.to_json()
    assert leaderboard_entries.migrate_directory(tmp_path) == [path]
    assert json.loads(path.read_text())["entry_version"] == 2 and leaderboard_entries.migrate_directory(tmp_path) == []


def test_unknown_versions_are_named(tmp_path):
    with pytest.raises(ValueError, match="entry_version 7"):
        Entry.from_json({**V1_ENTRY, "entry_version": 7})


def _gp_run(seeds: dict[int, float], commit: str, attacks=("identity",)) -> tuple[list[Row], dict, dict]:
    """Rows, settings and lens info of a run of co-designed `gp`: seed -> its trained Z4 coefficient."""
    rows, settings, info = [], {}, {}
    for seed, z4 in seeds.items():
        spec = {"name": "gp", "description": f"co-designed, seed {seed}",
                "mask": {"zernike_um": [0.0, 0.0, 0.0, z4], "bounds_um": [[-1, 1]] * 4}}
        for a in attacks:
            key = f"{a}-{seed}-{commit}"
            settings[key] = {"attacker": a, "lens": spec}
            rows.append(Row(kind="restorer", lens="gp", attack=a, restorer=a, seed=seed, profile="smoke",
                            scenes="synthetic", metrics={"psnr_db": 20.0 + seed}, settings_hash=key,
                            provenance={"git_commit": commit, "date": "d"}))
        info.setdefault("gp", {"spec": spec, "coefficients_um": spec["mask"]["zernike_um"]})
    return rows, settings, info


def test_seeds_of_a_co_designed_lens_published_apart_add_up(tmp_path):
    rows, settings, info = _gp_run({0: -0.3}, "aaa", attacks=("identity", "nafnet"))
    (path,) = leaderboard.publish(rows, PROFILE, info, tmp_path, settings)
    rows, settings, info = _gp_run({1: -0.5}, "bbb")  # seed 1 trained other coefficients: a new seed, not a new lens
    leaderboard.publish(rows, PROFILE, info, tmp_path, settings)
    entry = _load(path)
    assert entry.seeds == [0, 1] and entry.chain("identity").seeds == (0, 1)
    assert entry.chain("nafnet").seeds == (0,)
    # The entry's spec and coefficients stay its lowest seed's.
    assert entry.coefficients_um == [0.0, 0.0, 0.0, -0.3] and entry.lens_spec["description"].endswith("seed 0")


def test_a_seed_re_trained_into_other_coefficients_replaces_that_seed_whole(tmp_path):
    rows, settings, info = _gp_run({0: -0.3, 1: -0.5}, "aaa", attacks=("identity", "nafnet"))
    (path,) = leaderboard.publish(rows, PROFILE, info, tmp_path, settings)
    rows, settings, info = _gp_run({0: -0.1}, "bbb")  # seed 0 again, trained elsewhere: its old nafnet row goes too
    leaderboard.publish(rows, PROFILE, info, tmp_path, settings)
    entry = _load(path)
    assert entry.chain("identity").seeds == (0, 1) and entry.chain("nafnet").seeds == (1,)
    assert entry.coefficients_um == [0.0, 0.0, 0.0, -0.1]
    assert entry.chain("identity").rows[0].provenance["git_commit"] == "bbb"


def test_a_fixed_lens_with_other_coefficients_replaces_the_entry(tmp_path):
    rows, settings, info = _gp_run({0: -0.3}, "aaa")
    for r in rows:
        r.lens = "defocus"
    (path,) = leaderboard.publish(rows, PROFILE, {"defocus": info["gp"]}, tmp_path, settings)
    rows, settings, info = _gp_run({1: -0.5}, "bbb")
    for r in rows:
        r.lens = "defocus"
    leaderboard.publish(rows, PROFILE, {"defocus": info["gp"]}, tmp_path, settings)
    assert _load(path).seeds == [1]


def test_a_reference_without_a_spec_keeps_none_as_its_spec(tmp_path):
    rows = _rows(["identity"], "aaa", seeds=(0, 1))
    settings = {"identity-aaa": {"attacker": "identity", "lens": "sharp"}}  # what a run stores for `sharp`
    (path,) = leaderboard.publish(rows, PROFILE, {}, tmp_path, settings)
    leaderboard.publish(_rows(["identity"], "aaa", seeds=(0,)), PROFILE, {}, tmp_path, settings)
    entry = _load(path)
    assert entry.lens_spec is None and entry.coefficients_um is None and entry.seeds == [0, 1]


def test_nets_of_another_trainer_version_replace_the_entry(tmp_path):
    """A seed trained by a newer co-design trainer never sits beside seeds of the old one."""
    def run(seeds, commit, version):
        rows, settings, info = _gp_run(seeds, commit)
        for seed in seeds:
            rows.append(Row(kind="utility", lens="gp", attack="utility", seed=seed, profile="smoke",
                            scenes="synthetic", metrics={"miou": 0.2}, settings_hash=rows[0].settings_hash,
                            notes={} if version is None else {"trainer_version": version},
                            provenance={"git_commit": commit, "date": "d"}))
        return rows, settings, info

    rows, settings, info = run({0: -0.3, 1: -0.5}, "aaa", None)
    (path,) = leaderboard.publish(rows, PROFILE, info, tmp_path, settings)
    rows, settings, info = run({0: -0.2}, "bbb", "4")  # an old entry without the note: replaced
    leaderboard.publish(rows, PROFILE, info, tmp_path, settings)
    assert _load(path).seeds == [0]
    rows, settings, info = run({1: -0.4}, "ccc", "4")  # the same version: seeds add up
    leaderboard.publish(rows, PROFILE, info, tmp_path, settings)
    assert _load(path).seeds == [0, 1]
    rows, settings, info = run({1: -0.4}, "ddd", "5")  # another version: replaced
    leaderboard.publish(rows, PROFILE, info, tmp_path, settings)
    assert _load(path).seeds == [1] and _load(path).chain("utility").rows[0].provenance["git_commit"] == "ddd"
