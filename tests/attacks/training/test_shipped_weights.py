"""Attacker weights shipped in the package: found by their exact cache key, verified, and the same
network a fit would train; the shipped quick nafnet-generic is the one a quick run asks for."""

from __future__ import annotations

import json

import pytest
import torch

import attacks
from attacks.training import shipped_weights
from attacks.training.restorer_training import data_identity
from attacks.training.shipped_weights import ShippedWeightsError, find_shipped, same_data, write_shipped
from benchmark.store.cache import ArtifactCache


def _pairs():
    g = torch.Generator().manual_seed(0)
    sharp = torch.rand(4, 3, 32, 32, generator=g)
    yield sharp * 0.5, sharp


KEY = {"attack": "nafnet-generic", "budget": {"enc_blocks": (1, 2), "steps": 3}, "data": "abc", "seed": 0}


def test_found_by_the_exact_key_only(tmp_path):
    write_shipped("nafnet-generic-x", "nafnet-generic", KEY, b"weights", {"commit": "c"}, tmp_path)
    found = find_shipped("nafnet-generic", {**KEY, "budget": {"steps": 3, "enc_blocks": [1, 2]}}, tmp_path)
    assert found is not None and found.data == b"weights" and found.describe()["commit"] == "c"
    assert find_shipped("nafnet-generic", {**KEY, "seed": 1}, tmp_path) is None
    assert find_shipped("nafnet-known-pairs", KEY, tmp_path) is None


def _sensor_like(seed: int) -> torch.Tensor:
    g = torch.Generator().manual_seed(seed)
    scene = torch.rand(8, 3, 64, 64, generator=torch.Generator().manual_seed(0))
    return ((scene + 0.006 * torch.randn(scene.shape, generator=g)) * 1023).round().clamp(0, 1023) / 1023


def test_data_that_differs_by_float_rounding_is_the_same_data_and_another_noise_draw_is_not(tmp_path):
    sensor = _sensor_like(1)
    # Another CPU's rounding: 0.01 % of the pixels one ADC step off, which changes the byte hash.
    flipped = sensor.clone().flatten()
    flipped[torch.randperm(flipped.numel(), generator=torch.Generator().manual_seed(2))[:10]] += 1 / 1023
    flipped = flipped.reshape(sensor.shape)
    here, there, redrawn = data_identity(sensor), data_identity(flipped), data_identity(_sensor_like(3))
    assert here["sha256"] != there["sha256"]
    assert same_data(here, there) and same_data(here, here)
    assert not same_data(here, redrawn)  # the same scenes, another noise draw
    assert not same_data(here, data_identity(sensor[:4]))  # fewer images
    write_shipped("nafnet-known-pairs-x", "nafnet-known-pairs", {**KEY, "data": here}, b"w", {}, tmp_path)
    assert find_shipped("nafnet-known-pairs", {**KEY, "data": there}, tmp_path) is not None
    assert find_shipped("nafnet-known-pairs", {**KEY, "data": redrawn}, tmp_path) is None
    assert find_shipped("nafnet-known-pairs", {**KEY, "data": there, "seed": 1}, tmp_path) is None


def test_a_damaged_file_is_reported_with_its_path(tmp_path):
    path = write_shipped("nafnet-generic-x", "nafnet-generic", KEY, b"weights", {}, tmp_path)
    path.write_bytes(b"weightz")
    with pytest.raises(ShippedWeightsError, match="nafnet-generic-x.safetensors.*damaged"):
        find_shipped("nafnet-generic", KEY, tmp_path)
    path.unlink()
    with pytest.raises(ShippedWeightsError, match="missing"):
        find_shipped("nafnet-generic", KEY, tmp_path)


def test_a_malformed_provenance_is_reported_with_its_path(tmp_path):
    (tmp_path / "nafnet-generic-y.json").write_text("{not json")
    with pytest.raises(ShippedWeightsError, match="nafnet-generic-y.json"):
        find_shipped("nafnet-generic", KEY, tmp_path)
    (tmp_path / "nafnet-generic-y.json").write_text(json.dumps({"kind": "nafnet-generic"}))
    with pytest.raises(ShippedWeightsError, match="missing fields"):
        find_shipped("nafnet-generic", KEY, tmp_path)


def test_shipped_weights_are_what_the_fit_trains_and_replace_it(fake_lens, tmp_path, monkeypatch):
    ctx = attacks.FitContext(lens=fake_lens, train_pairs=_pairs, artifacts=ArtifactCache(tmp_path / "a"), seed=0)
    trained = attacks.load("nafnet-generic", backend="torch", use_shipped=False)
    trained.fit(ctx)
    assert trained.trained is True and trained.shipped is None
    from safetensors.torch import save
    state = {k: v.contiguous() for k, v in trained.network.state_dict().items()}
    write_shipped("nafnet-generic-tiny", "nafnet-generic", trained.cache_key(ctx), save(state), {"commit": "t"},
                  tmp_path / "shipped")
    monkeypatch.setattr(shipped_weights, "SHIPPED_DIR", tmp_path / "shipped")
    loaded = attacks.load("nafnet-generic", backend="torch")
    loaded.fit(attacks.FitContext(lens=fake_lens, train_pairs=_pairs, artifacts=ArtifactCache(tmp_path / "b"), seed=0))
    assert loaded.trained is False and loaded.shipped is not None
    assert not (tmp_path / "b").exists()  # neither trained nor cached
    assert loaded.describe()["shipped_weights"]["file"] == "nafnet-generic-tiny.safetensors"
    x = torch.rand(1, 3, 32, 32, generator=torch.Generator().manual_seed(1))
    assert torch.equal(loaded.restore(x), trained.restore(x))
    reseeded = attacks.load("nafnet-generic", backend="torch")
    reseeded.fit(attacks.FitContext(lens=fake_lens, train_pairs=_pairs, artifacts=ArtifactCache(tmp_path / "c"), seed=1))
    assert reseeded.trained is True and reseeded.shipped is None  # another seed: another key


@pytest.mark.slow
def test_the_shipped_quick_model_is_the_one_a_quick_run_asks_for_and_scores_its_record(tmp_path):
    from benchmark.publish.ship_attacker import check_scores, generic_context
    from benchmark.store.profiles import get_profile
    ctx = generic_context(get_profile("quick"), 0, tmp_path)
    attacker = attacks.load("nafnet-generic", backend="torch")
    attacker.fit(ctx)
    assert attacker.shipped is not None, ("no shipped nafnet-generic matches the quick seed-0 key; remake it with "
                                          "`python -m benchmark pretrain-attacker nafnet-generic`")
    assert attacker.trained is False
    recorded = attacker.shipped.provenance["made"]["check"]
    measured = check_scores(attacker, ctx)
    assert measured["psnr_in_db"] == pytest.approx(recorded["psnr_in_db"], abs=1e-3)
    assert measured["psnr_out_db"] == pytest.approx(recorded["psnr_out_db"], abs=0.05)
    assert measured["psnr_out_db"] > measured["psnr_in_db"] + 3.0  # it deblurs: not a random network


def test_the_packages_own_weights_are_found_where_the_package_ships_them():
    # Every provenance file the package ships names weights that find_shipped finds by its key, from the
    # default folder: a folder one level off would make every run retrain what the package ships.
    import json
    from pathlib import Path

    import attacks
    from attacks.training.shipped_weights import SHIPPED_DIR, find_shipped
    assert SHIPPED_DIR == Path(attacks.__file__).resolve().parent / "weights"
    provenances = sorted(SHIPPED_DIR.glob("*.json"))
    assert len(provenances) >= 4
    for path in provenances:
        prov = json.loads(path.read_text())
        found = find_shipped(prov["kind"], prov["key"])
        assert found is not None and found.path == path.with_suffix(".safetensors"), path.name


def test_a_described_data_field_matches_only_its_equal():
    described = {"scenes": "synthetic", "split": "train", "n": 64}
    assert same_data(described, dict(described))
    assert not same_data(described, {**described, "n": 65})
    assert not same_data(described, {"sha256": "abc", "summary": [0.1]})
