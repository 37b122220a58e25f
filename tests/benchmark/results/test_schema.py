"""The typed results schema: round trips, validation that names the field, and the v1 migration."""

import json
import math

import pytest

from benchmark.results.schema import Results, Row, RowError, migrate_legacy_row, read_results, rows_of_kind, settings_hash, write_results

IDS = {"lens": "defocus", "seed": 0, "profile": "smoke", "scenes": "synthetic"}
PROV = {"git_commit": "abc", "packages": "torch=2", "python": "3.12", "device": "cpu:x86_64", "threads": 2,
        "date": "2025-01-01T00:00:00+00:00", "wall_s": 1.5}


def legacy(attack, **metrics):
    return {**IDS, "attack": attack, **metrics, "config_hash": "0123456789abcdef", **PROV}


def test_round_trip_is_exact_and_strict_json():
    row = Row(kind="chain", attack="wiener-known-psf>lpdr", restorer="wiener-known-psf", reader="lpdr",
              metrics={"plate_acc": 0.25, "n_plates": 8}, threat_model="lens-access", settings_hash="h", **IDS,
              provenance=PROV)
    row.set_interval("plate_acc", 0.07, 0.59, "wilson")
    text = json.dumps(row.to_json(), allow_nan=False)
    again = Row.from_json(json.loads(text))
    assert again == row
    assert again.metric("n_plates") == 8.0 and again.interval("plate_acc") == (0.07, 0.59)
    assert again.metric("psnr_db") is None


@pytest.mark.parametrize("fields, named", [
    ({"kind": "restorr", "attack": "x", "restorer": "x"}, "kind"),
    ({"kind": "restorer", "attack": "x", "restorer": "y"}, "restorer"),
    ({"kind": "chain", "attack": "a>b", "restorer": "a", "reader": "c"}, "chain"),
    ({"kind": "lens", "attack": "utility"}, "lens row"),
    ({"kind": "restorer", "attack": "x", "restorer": "x", "metrics": {"psnr_db": math.nan}}, "psnr_db"),
    ({"kind": "restorer", "attack": "x", "restorer": "x", "metrics": {"psnr_db": math.inf}}, "psnr_db"),
    ({"kind": "restorer", "attack": "x", "restorer": "x", "metrics": {"threat_model": "known-pairs"}}, "threat_model"),
    ({"kind": "restorer", "attack": "x", "restorer": "x", "status": "failed", "metrics": {"psnr_db": 20.0},
      "error": RowError("x", "fit", "boom")}, "failed row"),
    ({"kind": "restorer", "attack": "x", "restorer": "x", "status": "broken"}, "status"),
])
def test_invalid_rows_name_what_is_wrong(fields, named):
    with pytest.raises(ValueError, match=named):
        Row(**IDS, **fields)


def test_unknown_or_missing_field_is_named():
    good = Row(kind="lens", attack="lens", **IDS).to_json()
    with pytest.raises(ValueError, match="psnr"):
        Row.from_json({**good, "psnr": 3.0})
    with pytest.raises(ValueError, match="scenes"):
        Row.from_json({k: v for k, v in good.items() if k != "scenes"})


def test_error_stage_must_be_known():
    with pytest.raises(ValueError, match="stage"):
        RowError("x", "training", "boom")


def test_legacy_rows_migrate_to_explicit_kinds():
    rows = [legacy("lens", psf_size_px=33, fit_s=0.1), legacy("utility", miou=0.4, mean_acc=0.5),
            legacy("bound", bound_bits_w32_t1=3.0, bound_assumptions="Gaussian", bound_plate_format="LLDDDD"),
            legacy("wiener-known-psf", psnr_db=24.0, ssim=0.7, threat_model="lens-access"),
            legacy("lpdr", plate_acc=0.5, n_plates=4, threat_model="sensor-access"),
            legacy("identity>lpdr", plate_acc=math.nan, n_plates=0, threat_model="sensor-access"),
            {**legacy("utility", miou=0.9), "lens": "sharp"}]
    migrated = [migrate_legacy_row(r) for r in rows]
    assert [(m.kind, m.restorer, m.reader) for m in migrated] == [
        ("lens", None, None), ("utility", None, None), ("bound", None, None), ("restorer", "wiener-known-psf", None),
        ("reader", None, "lpdr"), ("chain", "identity", "lpdr"), ("utility", None, None)]
    bound, chain = migrated[2], migrated[5]
    assert bound.notes == {"bound_assumptions": "Gaussian", "bound_plate_format": "LLDDDD"}
    assert "plate_acc" not in chain.metrics and chain.metric("n_plates") == 0.0  # NaN dropped, never scored
    assert migrated[3].threat_model == "lens-access" and "threat_model" not in migrated[3].metrics
    assert migrated[3].provenance == {**PROV, "legacy_config_hash": "0123456789abcdef"}
    assert migrated[6].lens == "sharp"


def test_results_file_round_trip_and_v1_migration(tmp_path):
    settings = {"lens": {"name": "defocus"}, "attack": {"name": "identity"}}
    key = settings_hash(settings)
    row = Row(kind="restorer", attack="identity", restorer="identity", metrics={"psnr_db": 20.0}, settings_hash=key,
              **IDS)
    failed = Row.failed("restorer", IDS["lens"], "broken", 0, "smoke", "synthetic", RowError("broken", "fit", "boom"),
                        restorer="broken")
    path = write_results(tmp_path / "results.json", Results([row, failed], {key: settings}, {"command": ["x"]}))
    back = read_results(path)
    assert back.rows == [row, failed] and back.settings[key] == settings
    assert rows_of_kind(back.rows, "restorer") == [row]
    assert rows_of_kind(back.rows, "restorer", ok_only=False) == [row, failed]
    (tmp_path / "v1.json").write_text(json.dumps({"schema_version": 1, "meta": {}, "rows": [legacy("lens", fit_s=1)]}))
    assert read_results(tmp_path / "v1.json").rows[0].kind == "lens"


def test_results_refuse_a_row_without_its_settings(tmp_path):
    row = Row(kind="lens", attack="lens", settings_hash="missing", **IDS)
    with pytest.raises(ValueError, match="missing"):
        write_results(tmp_path / "r.json", Results([row]))


def test_unreadable_results_name_the_file(tmp_path):
    path = tmp_path / "results.json"
    path.write_text(json.dumps({"schema_version": 7, "rows": []}))
    with pytest.raises(ValueError, match="results.json"):
        read_results(path)
