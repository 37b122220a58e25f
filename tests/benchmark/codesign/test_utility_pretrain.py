"""The clean utility pre-training and its shipped weights.

The shipped-weights test re-measures, on CPU, the mIoU that `python -m benchmark pretrain`
recorded for the first val scenes (its `check` block) and fails on a drift above TOLERANCE; the
fault tests corrupt a copy of a weights file and expect an error naming it.
"""

from __future__ import annotations

import json
import math
import shutil
from pathlib import Path

import numpy as np
import pytest
import torch

from benchmark.store.profiles import get_profile
from benchmark.scenes import load_scenes
from benchmark.codesign.utility.clean import (WEIGHTS_DIR, CorruptWeightsError, clean_utility_id, clean_utility_net, file_sha256, load_verified,
                                              provenance_path_for, shipped_for)
from benchmark.codesign.utility.pretrain import FINAL_LR_FRACTION, evaluate, learning_rate, load_val, main, plateau
from benchmark.codesign.utility.pretrain_data import RareClassCropSampler
from benchmark.codesign.utility.scoring import N_CLASSES

# mIoU over 2 scenes (about 1 M pixels) moves by far less than this when only BLAS summation order
# differs (threads, CPU); a changed net, scene generator or scoring moves it by more.
TOLERANCE = 0.005


def _shipped_quick() -> Path:
    path = shipped_for(get_profile("quick"))
    assert path is not None, f"no shipped weights in {WEIGHTS_DIR} match the quick profile"
    return path


@pytest.mark.slow
def test_shipped_weights_reach_their_recorded_miou():
    weights = _shipped_quick()
    provenance = json.loads(provenance_path_for(weights).read_text())
    assert provenance["file"]["bytes"] <= 20_000_000
    net = load_verified(weights, provenance["recipe"]["model"])
    torch.manual_seed(0)
    images, labels = load_val(provenance["check"]["val"])
    measured = evaluate(net, images, labels, provenance["check"]["val"])["miou"]
    assert abs(measured - provenance["check"]["miou"]) <= TOLERANCE, (measured, provenance["check"]["miou"])


def test_quick_uses_the_shipped_weights_and_other_profiles_do_not():
    assert shipped_for(get_profile("smoke")) is None
    assert shipped_for(get_profile("quick"), scene_set="cityscapes:/data/cityscapes") is None
    net = clean_utility_net(get_profile("quick"), seed=1, device="cpu", cache_dir=Path("/nonexistent"))
    reference = load_verified(_shipped_quick(), "b0")
    assert not net.training
    for (name, a), b in zip(net.state_dict().items(), reference.state_dict().values()):
        assert torch.equal(a, b), name


def _copy(weights: Path, folder: Path) -> Path:
    target = folder / weights.name
    shutil.copyfile(weights, target)
    shutil.copyfile(provenance_path_for(weights), provenance_path_for(target))
    return target


def test_a_flipped_byte_is_reported_with_the_path(tmp_path):
    copy = _copy(_shipped_quick(), tmp_path)
    data = bytearray(copy.read_bytes())
    data[len(data) // 2] ^= 0xFF
    copy.write_bytes(bytes(data))
    with pytest.raises(CorruptWeightsError, match="sha256") as info:
        load_verified(copy, "b0")
    assert str(copy) in str(info.value)


def test_a_truncated_file_is_reported_with_the_path(tmp_path):
    copy = _copy(_shipped_quick(), tmp_path)
    copy.write_bytes(copy.read_bytes()[:-100])
    with pytest.raises(CorruptWeightsError, match="bytes") as info:
        load_verified(copy, "b0")
    assert str(copy) in str(info.value)


def test_a_file_that_is_no_safetensors_is_refused_even_with_a_matching_hash(tmp_path):
    weights = tmp_path / "fake.safetensors"
    weights.write_bytes(b"\x80\x04not a safetensors file")  # e.g. a pickle
    provenance_path_for(weights).write_text(json.dumps(
        {"file": {"name": weights.name, "bytes": weights.stat().st_size, "sha256": file_sha256(weights)}}))
    with pytest.raises(CorruptWeightsError, match="cannot be loaded") as info:
        load_verified(weights, "tiny")
    assert str(weights) in str(info.value)


def test_missing_provenance_is_reported(tmp_path):
    weights = tmp_path / "w.safetensors"
    weights.write_bytes(b"x")
    with pytest.raises(CorruptWeightsError, match="no provenance") as info:
        load_verified(weights, "tiny")
    assert str(weights) in str(info.value)


def test_learning_rate_schedule_closed_form():
    steps, peak, warmup = 1000, 1e-3, 100
    assert learning_rate(0, steps, peak, warmup) == pytest.approx(peak / warmup)
    assert learning_rate(warmup - 1, steps, peak, warmup) == pytest.approx(peak)
    assert learning_rate(warmup, steps, peak, warmup) == pytest.approx(peak)
    middle = warmup + (steps - warmup) // 2
    final = FINAL_LR_FRACTION * peak
    assert learning_rate(middle, steps, peak, warmup) == pytest.approx(final + (peak - final) / 2)
    assert learning_rate(steps, steps, peak, warmup) == pytest.approx(final)
    lrs = [learning_rate(s, steps, peak, warmup) for s in range(warmup, steps)]
    assert all(a >= b for a, b in zip(lrs, lrs[1:]))


def test_plateau_criterion():
    curve = [{"step": s, "miou": m} for s, m in [(200, 0.20), (400, 0.30), (600, 0.35), (800, 0.40), (1000, 0.405)]]
    verdict = plateau(curve, 1000)
    assert verdict["from_step"] == 800 and verdict["gain_last_fifth"] == pytest.approx(0.005)
    assert verdict["reached"]
    curve[-1]["miou"] = 0.42
    assert not plateau(curve, 1000)["reached"]
    assert not plateau(curve[:-1], 1000)["reached"]  # an unfinished run has not plateaued


def test_rare_class_crops_balance_classes_and_batches_are_pure_functions_of_the_step():
    scenes = load_scenes("synthetic", "train", 4, (128, 256), 0)
    uniform = RareClassCropSampler(scenes, (32, 32), 16, seed=0, rare_fraction=0.0)
    rare = RareClassCropSampler(scenes, (32, 32), 16, seed=0, rare_fraction=1.0)

    def classes_seen(sampler: RareClassCropSampler) -> np.ndarray:
        present = np.zeros(N_CLASSES)
        for step in range(40):
            _, y = sampler.batch(step)
            for crop in y:
                present[np.unique(crop[crop < N_CLASSES].numpy())] += 1
        return present

    in_uniform, in_rare = classes_seen(uniform), classes_seen(rare)
    held = rare.classes
    # The rarest held classes are in more crops when crops are centred on uniformly drawn classes.
    rarest = sorted(held, key=lambda c: in_uniform[c])[:4]
    assert in_rare[rarest].sum() > 1.5 * in_uniform[rarest].sum()
    x1, y1 = rare.batch(7)
    x2, y2 = RareClassCropSampler(scenes, (32, 32), 16, seed=0, rare_fraction=1.0).batch(7)
    assert torch.equal(x1, x2) and torch.equal(y1, y2)
    assert x1.dtype == torch.float32 and x1.shape == (16, 3, 32, 32) and y1.shape == (16, 32, 32)


@pytest.mark.slow
def test_pretrain_command_exports_weights_that_load_and_reproduce_their_record(tmp_path, monkeypatch):
    monkeypatch.setenv("PLB_CACHE", str(tmp_path / "cache"))
    assert main(["--profile", "smoke", "--out", str(tmp_path / "w"), "--dir", str(tmp_path / "lb")]) == 0
    weights = tmp_path / "w" / "segformer-tiny-smoke.safetensors"
    provenance = json.loads(provenance_path_for(weights).read_text())
    assert provenance["file"]["sha256"] == file_sha256(weights)
    assert (tmp_path / "lb" / "charts" / "utility_pretrain.png").stat().st_size > 0
    assert json.loads((tmp_path / "lb" / "studies" / "utility_pretrain.json").read_text()) == provenance
    assert [p["step"] for p in provenance["curve"]] == [get_profile("smoke").pretrain_steps]
    net = load_verified(weights, "tiny")
    images, labels = load_val(provenance["val"])
    again = evaluate(net, images, labels, provenance["val"])
    assert again["miou"] == pytest.approx(provenance["final_shipped"]["miou"], abs=1e-9)
    assert not math.isnan(again["miou"])


def test_clean_utility_id_names_the_shipped_file_or_the_recipe():
    quick, smoke = get_profile("quick"), get_profile("smoke")
    assert clean_utility_id(quick, 0) == "shipped:" + file_sha256(_shipped_quick())
    assert clean_utility_id(quick, 0) == clean_utility_id(quick, 1)  # one shipped net starts every seed
    assert clean_utility_id(smoke, 0).startswith("recipe:")
    assert clean_utility_id(smoke, 0) != clean_utility_id(smoke, 1)
