"""A published run's pictures reach the leaderboard under stable names, listed on its charts page."""

from benchmark.publish import report as leaderboard_report
from benchmark.publish.leaderboard import copy_run_pictures, publish
from benchmark.results.schema import Row
from benchmark.store.profiles import get_profile


def test_first_sample_and_curves_are_copied_and_listed_and_the_run_width_chart_is_not(tmp_path):
    run, board = tmp_path / "run", tmp_path / "board"
    run.mkdir()
    (board / "samples").mkdir(parents=True)
    (board / "entries").mkdir()
    for name, data in (("samples_gp_seed0.png", b"s0"), ("samples_gp_seed1.png", b"s1"),
                       ("plate_accuracy_vs_width.png", b"w"), ("curves_gp_seed1.png", b"c1"),
                       ("curves_gp_seed0.png", b"c0")):
        (run / name).write_bytes(data)
    copied = copy_run_pictures(run, ["gp", "os"], "quick", board / "samples")
    # The width chart is drawn per entry by `report` from the entry's plates, never copied per run.
    assert [p.name for p in copied] == ["gp__quick.png", "gp__quick__curves.png"]
    assert (board / "samples" / "gp__quick.png").read_bytes() == b"s0"
    assert (board / "samples" / "gp__quick__curves.png").read_bytes() == b"c0"
    common = {"lens": "gp", "seed": 0, "profile": "quick", "scenes": "synthetic"}
    publish([Row(kind="utility", attack="utility", metrics={"miou": 0.3}, **common)], get_profile("quick").to_dict(),
            {}, board)
    leaderboard_report.render(board)
    text = (board / "charts.md").read_text()
    assert text.index("## Sample images") < text.index("samples/gp__quick.png)")
    assert text.index("## Co-design training curves") < text.index("samples/gp__quick__curves.png)")
