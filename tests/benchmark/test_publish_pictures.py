"""A published run's pictures reach the leaderboard under stable names, in their own README sections."""

from benchmark.publish import report as leaderboard_report
from benchmark.publish.leaderboard import copy_run_pictures


def test_first_sample_and_the_width_chart_are_copied_and_listed(tmp_path):
    run, board = tmp_path / "run", tmp_path / "board"
    run.mkdir()
    (board / "samples").mkdir(parents=True)
    (board / "entries").mkdir()
    for name, data in (("samples_gp_seed0.png", b"s0"), ("samples_gp_seed1.png", b"s1"),
                       ("plate_accuracy_vs_width.png", b"w"), ("curves_gp_seed1.png", b"c1"),
                       ("curves_gp_seed0.png", b"c0")):
        (run / name).write_bytes(data)
    copied = copy_run_pictures(run, ["gp", "os"], "quick", board / "samples")
    assert [p.name for p in copied] == ["gp__quick.png", "gp__quick__curves.png", "plate_width__quick__gp+os.png"]
    assert (board / "samples" / "gp__quick.png").read_bytes() == b"s0"
    assert (board / "samples" / "gp__quick__curves.png").read_bytes() == b"c0"
    leaderboard_report.render(board)
    text = (board / "README.md").read_text()
    width_at, samples_at = text.index("## Plate accuracy against plate width"), text.index("## Sample images")
    assert width_at < text.index("plate_width__quick__gp+os.png") < samples_at < text.index("gp__quick.png")
