"""The cache verifies what it reads, and its lock serialises holders."""

import logging
import multiprocessing
import time

from benchmark.store.cache import ArtifactCache, exclusive, read_verified, write_verified


def test_verified_round_trip_and_corruption_is_reported_and_removed(tmp_path, caplog):
    path = write_verified(tmp_path / "a" / "w.safetensors", b"x" * 100)
    assert read_verified(path) == b"x" * 100
    path.write_bytes(b"x" * 50)  # truncated
    with caplog.at_level(logging.WARNING):
        assert read_verified(path) is None
    assert str(path) in caplog.text and "checksum" in caplog.text
    assert not path.exists()  # removed: the producer rebuilds it
    assert read_verified(tmp_path / "missing") is None


def test_an_artifact_without_checksum_is_not_trusted(tmp_path):
    (tmp_path / "old.bin").write_bytes(b"legacy")
    assert read_verified(tmp_path / "old.bin") is None


def test_artifact_cache_keys_by_kind_and_config(tmp_path):
    store = ArtifactCache(tmp_path)
    store.save("nafnet", {"seed": 0}, b"zero")
    assert store.load("nafnet", {"seed": 0}) == b"zero"
    assert store.load("nafnet", {"seed": 1}) is None and store.load("other", {"seed": 0}) is None


def _hold(lock, log, tag, seconds=0.3):
    with exclusive(lock):
        with open(log, "a") as f:
            f.write(f"{tag}+")
        time.sleep(seconds)
        with open(log, "a") as f:
            f.write(f"{tag}-")


def test_exclusive_lets_one_holder_in_at_a_time(tmp_path):
    ctx = multiprocessing.get_context("spawn")
    procs = [ctx.Process(target=_hold, args=(tmp_path / "t.lock", tmp_path / "log", i)) for i in range(2)]
    for p in procs:
        p.start()
    for p in procs:
        p.join(30)
    text = (tmp_path / "log").read_text()
    assert text in ("0+0-1+1-", "1+1-0+0-"), text


def test_a_dead_holder_leaves_no_stale_lock(tmp_path):
    ctx = multiprocessing.get_context("spawn")
    p = ctx.Process(target=_hold, args=(tmp_path / "t.lock", tmp_path / "log", 0, 60))
    p.start()
    while not (tmp_path / "log").exists():  # until it holds the lock
        time.sleep(0.02)
    p.kill()
    p.join()
    t0 = time.perf_counter()
    with exclusive(tmp_path / "t.lock"):
        assert time.perf_counter() - t0 < 5
