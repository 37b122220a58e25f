"""The utility-size study trains each variant like the clean utility net and scores it like the runner."""

import dataclasses
import json

import pytest

from benchmark.publish import report as leaderboard_report
from benchmark.publish.profile_chart import utility_params
from benchmark.store.profiles import get_profile
from benchmark.studies import utility_size
from benchmark.codesign.utility import pretrain

pytestmark = pytest.mark.slow  # trains utility-net variants (15-20 s each)


def test_variants_are_trained_to_the_recipe_measured_compared_and_charted(tmp_path):
    profile = get_profile("smoke")
    records = utility_size.measure(profile, ("tiny", "b0-narrow"), cache_dir=tmp_path / "cache")
    assert [r["variant"] for r in records] == ["tiny", "b0-narrow"]
    assert [r["params"] for r in records] == [utility_params("tiny"), utility_params("b0-narrow")]
    for r in records:
        # IoU_c = TP / (TP + FP + FN) <= TP / (TP + FN) = accuracy_c, class by class.
        assert 0.0 <= r["miou"] <= r["mean_acc"] + 1e-12 <= 1.0 + 1e-12
        assert 0.0 <= r["overall_acc"] <= 1.0 and r["images_per_s"] > 0
        for name in utility_size.SCORES:
            low, high = r["intervals"][name]
            assert low <= r[name] + 1e-12 and r[name] <= high + 1e-12
        # Trained by the clean pre-training's own recipe: its whole learning curve and plateau verdict.
        assert r["steps"] == profile.pretrain_steps and r["curve"][-1]["step"] == profile.pretrain_steps
        assert set(r["plateau"]) >= {"reached", "gain_last_fifth"} and r["train_s"] > 0
        for name, shares in r["predicted_as"].items():
            assert 0.0 < sum(shares.values()) <= 1.0 + 1e-9 and list(shares.values()) == sorted(shares.values())[::-1]
    # Only the smaller variant is compared with the largest, on the same scenes.
    assert "vs_largest" not in records[-1]
    versus = records[0]["vs_largest"]
    assert versus["n_scenes"] == profile.n_val
    assert versus["difference"] == records[1]["miou"] - records[0]["miou"]
    assert versus["verdict"].split(":")[0] in ("holds", "does not hold", "cannot tell at this sample size")

    # Cached like the clean net (the same recipe hash): a second measurement trains nothing and reports
    # the seconds the training took when it ran, not the load time.
    again = utility_size.measure(profile, ("tiny",), cache_dir=tmp_path / "cache")
    assert again[0]["miou"] == records[0]["miou"] and again[0]["train_s"] == records[0]["train_s"]
    _, trained = pretrain.train(dataclasses.replace(profile, utility_model="tiny"), 0, "cpu",
                                tmp_path / "cache", progress=False)
    assert trained["timing"]["train_s"] == records[0]["train_s"]

    (tmp_path / "entries").mkdir()
    (tmp_path / "studies").mkdir()
    (tmp_path / "studies" / "utility_size.json").write_text(json.dumps({"records": records, "profile": {}}))
    assert tmp_path / "charts" / "utility_size.png" in leaderboard_report.render(tmp_path)


def test_an_older_study_without_intervals_or_curves_still_charts(tmp_path):
    """The study JSON published before the plateau rework (no intervals, no curves) renders."""
    records = [{"variant": "tiny", "params": 245483, "miou": 0.09, "images_per_s": 0.3, "train_s": 187.0},
               {"variant": "b0", "params": 3719027, "miou": 0.17, "images_per_s": 0.2, "train_s": 0.1}]
    (tmp_path / "entries").mkdir()
    (tmp_path / "studies").mkdir()
    (tmp_path / "studies" / "utility_size.json").write_text(json.dumps({"records": records, "profile": {}}))
    assert tmp_path / "charts" / "utility_size.png" in leaderboard_report.render(tmp_path)


def test_predicted_as_reads_the_confusion_rows():
    import numpy as np
    confusion = np.zeros((19, 19))
    confusion[13, 13], confusion[14, 13], confusion[14, 14], confusion[14, 0] = 10, 6, 3, 1  # truck: 6 car, 3 truck
    shares = utility_size.predicted_as(confusion)
    assert shares == {"car": {"car": 1.0}, "truck": {"car": 0.6, "truck": 0.3, "road": 0.1}}


def test_a_variant_may_name_its_crop_and_is_compared_with_the_profile_crop(tmp_path):
    profile = get_profile("smoke")
    assert utility_size.parse_variant("tiny@32", profile).pretrain_crop == (32, 32)
    assert utility_size.parse_variant("tiny", profile).pretrain_crop == profile.pretrain_crop
    for bad in ("tiny@x", "tiny@0", "tiny@4096"):
        with pytest.raises(ValueError, match="utility-size variant"):
            utility_size.parse_variant(bad, profile)
    records = utility_size.measure(profile, ("tiny", "tiny@32"), cache_dir=tmp_path / "cache")
    assert records[1]["pretrain_crop"] == [32, 32] and records[1]["model"] == "tiny"
    assert records[1]["params"] == records[0]["params"] and "vs_largest" not in records[0]
    versus = records[1]["vs_profile_crop"]
    assert versus["difference"] == records[1]["miou"] - records[0]["miou"]


def test_the_profile_model_is_checked_against_the_shipped_weights_it_reproduces(tmp_path, monkeypatch):
    """Shipped weights exported from the very net the study trains: zero weight difference, the same
    mIoU up to float16 rounding; another variant gets no such check."""
    profile = get_profile("smoke")
    net, record = pretrain.train(profile, 0, "cpu", tmp_path / "cache", progress=False)
    weights, _ = pretrain.export(net, record, profile, tmp_path / "weights")
    monkeypatch.setattr(utility_size.clean, "shipped_for", lambda p, scene_set="synthetic": weights)
    records = utility_size.measure(profile, ("b0-narrow", profile.utility_model), cache_dir=tmp_path / "cache")
    assert "shipped" not in records[0]
    shipped = records[1]["shipped"]
    assert shipped["file"] == weights.name and shipped["max_abs_weight_difference"] == 0.0
    assert abs(shipped["miou"] - records[1]["miou"]) < 0.02
