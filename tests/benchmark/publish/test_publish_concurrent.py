"""Two publishes into one leaderboard at once keep both runs' rows: publishing
holds the leaderboard folder's lock from reading the stored entry to rendering the pages, and a
render alone waits for it."""

from __future__ import annotations

import multiprocessing
import threading
import time

from benchmark.publish import leaderboard
from benchmark.publish import report as leaderboard_report
from benchmark.results.entries import LOCK_FILE, migrate_directory, read_entry
from benchmark.results.schema import Row
from benchmark.store.cache import exclusive

PROFILE = {"name": "smoke", "n_val": 4, "image_size": [128, 256]}


def _rows(attack: str, commit: str) -> list[Row]:
    return [Row(kind="restorer", lens="ideal", attack=attack, restorer=attack, seed=0, profile="smoke",
                scenes="synthetic", metrics={"psnr_db": 20.0}, provenance={"git_commit": commit})]


def _publish_slowly(board, run, attack, barrier) -> None:
    """Publish one run's rows, with the merge slowed down so that, without the lock, both processes
    read the stored entry before either writes its own (the race of `report --publish A & ... B`)."""
    merge = leaderboard.merge_entries

    def slow_merge(old, new):
        time.sleep(1.0)
        return merge(old, new)

    leaderboard.merge_entries = slow_merge
    barrier.wait(60)
    leaderboard.publish_run(_rows(attack, attack), PROFILE, {}, run, board)


def test_two_concurrent_publishes_keep_both_runs_rows(tmp_path):
    board, run = tmp_path / "board", tmp_path / "run"
    run.mkdir()
    (path,) = leaderboard.publish(_rows("identity", "first"), PROFILE, {}, board)  # what both merge into
    # fork: the children start in milliseconds with the modules already imported (spawn: ~5 s each).
    ctx = multiprocessing.get_context("fork")
    barrier = ctx.Barrier(2)
    procs = [ctx.Process(target=_publish_slowly, args=(board, run, attack, barrier))
             for attack in ("wiener-known-psf", "richardson-lucy-known-psf")]
    for p in procs:
        p.start()
    for p in procs:
        p.join(120)
    assert [p.exitcode for p in procs] == [0, 0]
    entry = read_entry(path)
    assert sorted(c.attack for c in entry.chains()) == ["identity", "richardson-lucy-known-psf", "wiener-known-psf"]
    # Each row keeps the provenance of the run that measured it ...
    assert {c.attack: c.rows[0].provenance["git_commit"] for c in entry.chains()} == {
        "identity": "first", "wiener-known-psf": "wiener-known-psf",
        "richardson-lucy-known-psf": "richardson-lucy-known-psf"}
    # ... and the pages rendered last show every row: no render ran on an older set of entries.
    attackers = (board / "attackers.md").read_text()  # every attacker's line (the README keeps the headline)
    assert all(f"| ideal | {attack} |" in attackers
               for attack in ("identity", "wiener-known-psf", "richardson-lucy-known-psf"))


def test_a_render_or_a_migration_waits_for_a_publish_in_progress(tmp_path):
    # `report` alone renders (and `report --migrate` rewrites entries); beside a publish neither may
    # write from entries read before that publish wrote its rows, so both wait for the lock.
    board = tmp_path / "board"
    leaderboard.publish(_rows("identity", "first"), PROFILE, {}, board)
    with exclusive(board / LOCK_FILE):  # what a publish in another process holds
        workers = [threading.Thread(target=f, args=(board,)) for f in (leaderboard_report.render, migrate_directory)]
        for worker in workers:
            worker.start()
        time.sleep(1.0)
        assert all(w.is_alive() for w in workers) and not (board / "README.md").exists()
    for worker in workers:
        worker.join(60)
    assert not any(w.is_alive() for w in workers)
    assert "| ideal | identity |" in (board / "attackers.md").read_text()
