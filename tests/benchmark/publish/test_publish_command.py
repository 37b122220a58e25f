"""`python -m benchmark publish`: one resumable run of the lenses with the standard ensemble whose entries
replace the published ones whole, with a progress bar over the plan's estimated seconds."""

from __future__ import annotations

import dataclasses
import io
import json
import sys
from types import SimpleNamespace

import pytest

import benchmark
from benchmark import cli
from benchmark.publish import leaderboard, republish
from benchmark.runner.defaults import STANDARD_ENSEMBLE
from benchmark.results.entries import read_entry
from benchmark.runner.task_costs import Estimate
from benchmark.store.measured_costs import Quote
from benchmark.store.profiles import get_profile


def _task(key, kind, seconds=None, cached=False, table=None, seed=0, lens="l"):
    return SimpleNamespace(key=key, kind=kind, seed=seed, lens=lens, cached=cached,
                           estimate=Estimate(seconds, 0 if table is not None or seconds is None else 3, table))


def test_task_weights_count_each_task_once_at_its_estimate():
    together = Quote(6.0, True, False, "m", None)
    planned = [_task("a", "fit", 10.0), _task("b", "fit", 30.0), _task("c", "fit"),  # c: the fits' median
               _task("d", "evaluate"),                                            # no evaluate known: all's median
               _task("e", "lens", 99.0, cached=True),                             # read back
               _task("f", "lens", None, table=Quote(None, False, False, "m", None)),  # installed
               _task("g", "fit", 6.0, table=together), _task("h", "fit", 6.0, table=together),
               _task("i", "fit", 6.0, table=together, lens="other")]
    weights = republish.task_weights(planned)
    # g and h share one figure for their lens; i has it alone; the median of the known is taken before.
    assert weights.seconds == {"a": 10.0, "b": 30.0, "c": 6.0, "d": 6.0, "e": republish.CACHED_S,
                               "f": republish.CACHED_S, "g": 3.0, "h": 3.0, "i": 6.0}
    assert weights.guessed == 2 and weights.total == pytest.approx(sum(weights.seconds.values()))
    bar = republish.EtaBar(weights, file=io.StringIO())
    for t in planned[:3]:
        bar(t)
    assert bar.bar.n == pytest.approx(46.0) and bar.done == ["a", "b", "c"]
    bar.close()


@pytest.mark.slow
def test_publish_replaces_entries_whole_and_resumes_from_the_cache(tmp_path, capsys):
    board, out = tmp_path / "board", tmp_path / "run"
    (board / "entries").mkdir(parents=True)
    old = benchmark.run(["defocus"], ["identity", "lpdr-oracle"], profile="smoke", out=tmp_path / "old")
    leaderboard.publish_run(old.output.rows, get_profile("smoke").to_dict(), old.output.lens_info, tmp_path / "old",
                            board, old.output.settings)
    entry = board / "entries" / "defocus__smoke__synthetic.json"
    assert {"lpdr-oracle", "identity>lpdr-oracle"} <= {r.attack for r in read_entry(entry).rows}
    argv = ["publish", "--lens", "defocus", "--profile", "smoke", "--seeds", "0", "--dir", str(board), "--out", str(out)]
    assert cli.main(argv) == 0
    printed = capsys.readouterr().out
    assert "publish defocus (smoke, seeds 0):" in printed and "published 2 leaderboard entries" in printed
    attacks = {r.attack for r in read_entry(entry).rows if r.kind in ("restorer", "reader", "chain", "reference")}
    # The older run's lpdr-oracle rows are gone; only the standard ensemble's chains are there (the known-PSF
    # and learned attackers of a fixed lens).
    assert attacks <= set(STANDARD_ENSEMBLE) and not {"lpdr-oracle", "identity>lpdr-oracle"} & attacks
    assert {"demosaic-vng>learned-reader", "demosaic-vng>learned-reader-psf", "nafnet-known-psf>lpdr"} <= attacks
    # Run again: every task comes from the cache.
    plan = benchmark.plan(["defocus"], profile="smoke", seeds=[0])
    assert all(t.cached for t in plan.tasks)
    assert cli.main(argv) == 0
    assert "(0 to compute," in capsys.readouterr().out


def _fake_lens_processes(monkeypatch, scripts):
    """Make each lens process run a small Python script instead of a benchmark run."""
    monkeypatch.setattr(republish, "lens_command",
                        lambda lens, *rest: [sys.executable, "-c", scripts[lens]])


def test_lens_processes_log_each_process_and_stop_at_one_that_died(tmp_path, monkeypatch):
    scripts = {"a": ("import sys, time; block = bytearray(300 * 2**20); block[::4096] = b'x' * len(block[::4096]); "
                     "time.sleep(0.5); sys.exit(1)"),
               "b": "import os, signal; os.kill(os.getpid(), signal.SIGKILL)",
               "c": "pass"}
    _fake_lens_processes(monkeypatch, scripts)
    lines = []
    parts = republish.lens_processes([("a", 0, 3, 60.0), ("b", 1, 2, 30.0), ("c", 1, 1, 5.0)], "smoke", "cpu",
                                     tmp_path, "v1", echo=lines.append)
    # a: failed rows (exit 1) do not stop the publish; b was killed: c never starts.
    assert [p.lens for p in parts] == ["a", "b"]
    assert parts[0].returncode == 1 and parts[1].returncode == -9 and [p.seed for p in parts] == [0, 1]
    assert [p.died for p in parts] == [False, True]
    # The child's own peak: it touched 300 MiB; the test process's own memory (over 1 GiB with torch) is not in it.
    assert 300 <= parts[0].peak_rss_mib < 1000
    assert "the process died (exit status -9)" in lines[-1]
    logged = republish.read_log(tmp_path)
    assert logged == parts
    # Another version's parts and a torn last line are not counted.
    with open(tmp_path / republish.LOG_NAME, "a") as f:
        f.write(json.dumps({**dataclasses.asdict(parts[0]), "code_version": "v0"}) + "\n" + '{"lens": "c", "wa')
    assert republish.read_log(tmp_path, "v1") == parts
    assert len(republish.read_log(tmp_path)) == 3
    summary = republish.log_summary(parts)
    assert summary.startswith(f"2 processes, {parts[0].wall_s + parts[1].wall_s:.0f} s")
    assert f"peak {max(p.peak_rss_mib for p in parts) / 1024:.2f} GiB" in summary


def test_lens_command_computes_one_lens_and_publishes_nothing(tmp_path):
    command = republish.lens_command("gp", "quick", [0, 2], "cpu", tmp_path / "lenses" / "gp")
    assert command[:3] == [sys.executable, "-m", cli.__package__]  # the package whose parser reads it below
    args = cli.build_parser().parse_args(command[3:])
    assert args.compute_only and args.lens == ["gp"] and args.seeds == [0, 2] and args.out == tmp_path / "lenses" / "gp"


def test_a_publish_runs_one_process_per_lens_and_seed_with_work_and_each_shared_task_once():
    planned = [_task("sharp_s0", "sharp", 70.0, seed=0, lens=""), _task("sharp_s1", "sharp", 70.0, seed=1, lens=""),
               _task("eval_s0_a", "evaluate", 300.0, seed=0, lens="a"), _task("eval_s1_a", "evaluate", 300.0, seed=1,
                                                                                lens="a", cached=True),
               _task("eval_s0_b", "evaluate", 200.0, seed=0, lens="b"), _task("eval_s1_b", "evaluate", 200.0, seed=1,
                                                                                lens="b")]
    parts = republish.lens_seed_parts(planned, ["b", "a"], [0, 1], republish.task_weights(planned))
    # b first, as given; its processes compute each seed's shared task; a's seed 1 is all cached.
    assert parts == [("b", 0, 2, 270.0), ("b", 1, 2, 270.0), ("a", 0, 1, 300.0)]
