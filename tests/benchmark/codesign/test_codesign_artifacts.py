"""Fault injection: every artifact that co-design, the adversary's pre-training and
the clean utility pre-training write under the cache is checked on read; a truncated one is reported
with its path and rebuilt, and the rebuilt run equals a clean one (all of it is seeded on the CPU)."""

import dataclasses
import logging
import shutil
from pathlib import Path

import pytest
import torch

from benchmark.store.cache import read_verified
from benchmark.codesign.codesigned_lenses import START_SPEC
from benchmark.codesign.schemes import SCHEMES
from benchmark.codesign.trainer import CoDesign
from benchmark.scenes.plate_spectrum import cached_plate_spectrum
from benchmark.store.profiles import PROFILES
from benchmark.codesign.utility import pretrain
from lenses.spec import load_spec

pytestmark = pytest.mark.slow  # each case co-designs a tiny lens again (3-12 s)

# The smallest profile that runs every part: clean pre-training, adversary pre-training, co-design.
TINY = dataclasses.replace(PROFILES["smoke"], image_size=(64, 128), n_train=2, train_crop=(48, 48), batch_size=2,
                           codesign_steps=2, pretrain_steps=1, utility_model="tiny", adversary_width=4)
# Clean pre-training long enough to checkpoint before it ends (a curve point, hence a checkpoint, per step).
PRETRAIN = dataclasses.replace(TINY, pretrain_steps=2, pretrain_eval_every=1, n_val=1)


def codesign(cache: Path) -> CoDesign:
    return CoDesign(load_spec(START_SPEC), SCHEMES["gp"], TINY, 0, "cpu", cache)


def outcome(trained) -> dict:
    return {"coefficients_um": trained.record["final_coefficients_um"],
            "utility": trained.utility_net.state_dict(), "adversary": trained.adversary.state_dict()}


def assert_same(a: dict, b: dict) -> None:
    assert a["coefficients_um"] == b["coefficients_um"]
    for net in ("utility", "adversary"):
        assert a[net].keys() == b[net].keys()
        assert all(torch.equal(a[net][k], b[net][k]) for k in a[net]), net


@pytest.fixture(scope="module")
def clean_cache(tmp_path_factory):
    """A cache after one uninterrupted co-design run, and what that run produced."""
    cache = tmp_path_factory.mktemp("clean")
    return cache, outcome(codesign(cache).train(progress=False))


def _only(folder: Path, pattern: str) -> Path:
    (path,) = [p for p in folder.glob(pattern) if not p.name.endswith(".sha256")]
    return path


def _published(cache: Path, name: str) -> Path:
    return codesign(cache).directory / name


def _interrupted_codesign_checkpoint(cache: Path) -> Path:
    shutil.rmtree(codesign(cache).directory)
    with pytest.raises(KeyboardInterrupt):
        codesign(cache).train(progress=False, stop_after=1)
    return codesign(cache).checkpoint_path


def _before_codesign(pattern: str):
    """An artifact read only while co-design trains: its finished run is removed, so the rerun trains."""
    def find(cache: Path) -> Path:
        shutil.rmtree(codesign(cache).directory)
        return _only(cache, pattern)
    return find


ARTIFACTS = {
    "codesign checkpoint": _interrupted_codesign_checkpoint,
    **{f"codesign {name}": (lambda cache, n=name: _published(cache, n))
       for name in ("lens.toml", "utility.safetensors", "adversary.safetensors", "record.json", "curves.jsonl",
                    "curves.png")},
    "adversary weights": _before_codesign("adversary/red10-*.safetensors"),
    "adversary record": _before_codesign("adversary/red10-*.json"),
    "clean net weights": _before_codesign("utility/clean-*.safetensors"),
    "clean net record": _before_codesign("utility/clean-*.json"),
}


def truncate(path: Path) -> None:
    data = path.read_bytes()
    path.write_bytes(data[: len(data) // 2])


@pytest.mark.parametrize("kind", ARTIFACTS)
def test_a_truncated_codesign_artifact_is_reported_and_rebuilt(kind, clean_cache, tmp_path, caplog):
    reference_cache, reference = clean_cache
    cache = tmp_path / "cache"
    shutil.copytree(reference_cache, cache)
    path = ARTIFACTS[kind](cache)
    truncate(path)
    with caplog.at_level(logging.WARNING):
        rerun = codesign(cache).load_or_train(progress=False)
    assert str(path) in caplog.text  # reported with its path
    if kind != "codesign checkpoint":  # rebuilt (a finished run drops its checkpoint)
        assert read_verified(path) is not None
    assert_same(outcome(rerun), reference)
    assert_same(outcome(codesign(cache).load()), reference)  # and what is cached now loads


def _pretrain(cache: Path, interrupt_at_point: int | None = None):
    """Clean pre-training on PRETRAIN; `interrupt_at_point` stops it there, after that curve point's checkpoint."""
    if interrupt_at_point is None:
        return pretrain.train(PRETRAIN, 0, "cpu", cache, progress=False)
    original, calls = pretrain.evaluate, []

    def evaluate(*args, **kwargs):
        calls.append(1)
        if len(calls) > interrupt_at_point:
            raise KeyboardInterrupt("interrupted")
        return original(*args, **kwargs)

    pretrain.evaluate = evaluate
    try:
        with pytest.raises(KeyboardInterrupt):
            pretrain.train(PRETRAIN, 0, "cpu", cache, progress=False)
    finally:
        pretrain.evaluate = original


def test_a_truncated_pretraining_checkpoint_restarts_from_step_0(tmp_path, caplog):
    reference_net, reference_record = _pretrain(tmp_path / "clean")
    _pretrain(tmp_path / "cache", interrupt_at_point=1)
    (checkpoint,) = (tmp_path / "cache" / "utility").glob("*.checkpoint.pt")
    truncate(checkpoint)
    with caplog.at_level(logging.WARNING):
        net, record = _pretrain(tmp_path / "cache")
    assert str(checkpoint) in caplog.text and "restarts from step 0" in caplog.text
    assert not checkpoint.exists()
    assert [p["step"] for p in record["curve"]] == [1, 2]
    assert [p["miou"] for p in record["curve"]] == [p["miou"] for p in reference_record["curve"]]
    assert all(torch.equal(v, reference_net.state_dict()[k]) for k, v in net.state_dict().items())


def test_a_truncated_plate_spectrum_is_reported_and_rebuilt(tmp_path, caplog):
    reference = cached_plate_spectrum(tmp_path, 3)
    (path,) = (tmp_path / "bound").glob("plate-spectrum-*.json")
    truncate(path)
    with caplog.at_level(logging.WARNING):
        rebuilt = cached_plate_spectrum(tmp_path, 3)
    assert str(path) in caplog.text and read_verified(path) is not None
    assert (rebuilt.table == reference.table).all() and rebuilt.min_radiance == reference.min_radiance
