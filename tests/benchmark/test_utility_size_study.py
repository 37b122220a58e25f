"""The utility-size study trains each variant like the clean utility net and scores it like the runner."""

import json

from benchmark import leaderboard_report
from benchmark.charts.profiles import utility_params
from benchmark.profiles import get_profile
from benchmark.studies import utility_size


def test_variants_are_measured_and_charted(tmp_path):
    profile = get_profile("smoke")
    records = utility_size.measure(profile, ("tiny", "b0-narrow"), cache_dir=tmp_path / "cache")
    assert [r["variant"] for r in records] == ["tiny", "b0-narrow"]
    assert [r["params"] for r in records] == [utility_params("tiny"), utility_params("b0-narrow")]
    for r in records:
        # IoU_c = TP / (TP + FP + FN) <= TP / (TP + FN) = accuracy_c, class by class.
        assert 0.0 <= r["miou"] <= r["mean_acc"] + 1e-12 <= 1.0 + 1e-12
        assert 0.0 <= r["overall_acc"] <= 1.0 and r["images_per_s"] > 0
    # Cached like the runner's clean net: a second measurement loads the same weights.
    again = utility_size.measure(profile, ("tiny",), cache_dir=tmp_path / "cache")
    assert again[0]["miou"] == records[0]["miou"]
    (tmp_path / "entries").mkdir()
    (tmp_path / "studies").mkdir()
    (tmp_path / "studies" / "utility_size.json").write_text(json.dumps({"records": records, "profile": {}}))
    assert tmp_path / "charts" / "utility_size.png" in leaderboard_report.render(tmp_path)
