"""Scene sets: determinism, split hygiene, class coverage and honest plate ground truth."""

from __future__ import annotations

import itertools
import math

import numpy as np
import pytest
import torch

from benchmark.scenes import (CLASS_NAMES, PLATE_FORMAT, SCENE_SETS, TRAIN_ID, SceneDataset, load_scene, load_scenes, matches_format,
                              plate_entropy_bits, scene_seed)
from benchmark.scenes.dataset import crop_scene, flip_scene
from benchmark.scenes.photos import PHOTO_SPLITS

SMALL = (256, 512)
PLATE_CLASSES = {TRAIN_ID["car"], TRAIN_ID["truck"], TRAIN_ID["bus"]}


@pytest.fixture(scope="module")
def small_scenes():
    return load_scenes("synthetic", "train", 16, size=SMALL, seed=0)


@pytest.fixture(scope="module")
def full_scenes():
    return load_scenes("synthetic", "val", 16, seed=0)


def _same(a, b) -> bool:
    return (np.array_equal(a.image, b.image) and np.array_equal(a.labels, b.labels) and a.plates == b.plates
            and a.vehicles == b.vehicles and a.seed == b.seed)


def test_same_arguments_give_bit_identical_scenes():
    first = load_scenes("synthetic", "test", 2, size=(64, 128), seed=5)
    again = load_scenes("synthetic", "test", 2, size=(64, 128), seed=5)
    assert all(_same(a, b) for a, b in zip(first, again))


def test_scene_depends_on_seed_and_not_on_n():
    a = load_scene("synthetic", "test", 1, size=(64, 128), seed=5)
    assert _same(a, load_scenes("synthetic", "test", 3, size=(64, 128), seed=5)[1])
    b = load_scene("synthetic", "test", 1, size=(64, 128), seed=6)
    assert not np.array_equal(a.image, b.image)


def test_splits_never_share_a_scene_seed():
    seeds = {split: {scene_seed(split, s, i) for s in range(3) for i in range(300)}
             for split in ("train", "val", "test")}
    assert all(len(v) == 900 for v in seeds.values())
    for a, b in itertools.combinations(seeds.values(), 2):
        assert not a & b


def test_scene_records_have_contract_shapes_and_ranges(small_scenes):
    for scene in small_scenes:
        assert scene.image.shape == (*SMALL, 3) and scene.image.dtype == np.float32
        assert 0.0 <= scene.image.min() and scene.image.max() <= 1.0
        assert scene.labels.shape == SMALL and scene.labels.dtype == np.uint8
        assert set(np.unique(scene.labels)) <= set(range(19)) | {255}


def test_all_19_classes_are_covered(small_scenes):
    seen = set().union(*(np.unique(s.labels).tolist() for s in small_scenes))
    assert {CLASS_NAMES[i] for i in range(19)} - {CLASS_NAMES[i] for i in seen if i < 19} == set()


def test_textures_are_not_flat_colours(small_scenes):
    scene = small_scenes[0]
    for name in ("road", "building", "vegetation"):
        pixels = scene.image[scene.labels == TRAIN_ID[name]]
        assert pixels.std(axis=0).mean() > 0.02, name


def test_plate_ground_truth_matches_pixels(small_scenes):
    n_plates = 0
    for scene in small_scenes:
        height, width = scene.labels.shape
        for k, plate in enumerate(scene.plates):
            n_plates += 1
            x1, y1, x2, y2 = plate.box_xyxy
            assert 0 <= x1 < x2 <= width and 0 <= y1 < y2 <= height
            assert matches_format(plate.text) and not plate.mirrored
            vehicle = scene.vehicles[plate.vehicle_index]
            assert vehicle.train_id in PLATE_CLASSES
            vx1, vy1, vx2, vy2 = vehicle.box_xyxy
            assert vx1 <= x1 and vy1 <= y1 and x2 <= vx2 and y2 <= vy2
            visible = scene.plate_mask == k + 1
            assert visible[y1:y2, x1:x2].sum() == visible.sum() > 0
            assert np.all(scene.labels[visible] == vehicle.train_id)
            assert 0.0 < plate.visible_fraction <= 1.0
            if plate.visible_fraction == 1.0:
                assert visible.sum() == (x2 - x1) * (y2 - y1)
    assert n_plates >= 30


def test_occluded_plates_report_partial_visibility(full_scenes):
    fractions = [p.visible_fraction for s in full_scenes for p in s.plates]
    assert any(f < 1.0 for f in fractions) and sum(f == 1.0 for f in fractions) > len(fractions) / 2


def test_plate_widths_span_unreadable_to_large(full_scenes):
    widths = [p.box_xyxy[2] - p.box_xyxy[0] for s in full_scenes for p in s.plates if p.visible_fraction == 1.0]
    assert min(widths) <= 12 and 120 <= max(widths) <= 190
    assert sum(w >= 40 for w in widths) >= 5


def test_large_plates_show_dark_text_on_light_ground(full_scenes):
    checked = 0
    for scene in full_scenes:
        for plate in scene.plates:
            x1, y1, x2, y2 = plate.box_xyxy
            if x2 - x1 >= 60 and plate.visible_fraction == 1.0:
                luma = scene.image[y1:y2, x1:x2].mean(axis=2)
                # Bold text covers about half of a plate: its light ground is the upper quartile.
                assert np.percentile(luma, 75) > 0.5 and luma.min() < 0.2
                checked += 1
    assert checked >= 3


def test_plate_text_follows_format_and_entropy_has_closed_form(small_scenes):
    texts = [p.text for s in small_scenes for p in s.plates]
    assert all(len(t) == len(PLATE_FORMAT) and t.isalnum() and t.upper() == t for t in texts)
    assert len(set(texts)) == len(texts)
    n_letters, n_digits = PLATE_FORMAT.count("L"), PLATE_FORMAT.count("D")
    assert plate_entropy_bits() == pytest.approx(n_letters * math.log2(26) + n_digits * math.log2(10))
    assert plate_entropy_bits("LD") == pytest.approx(math.log2(260))
    with pytest.raises(ValueError, match="X"):
        plate_entropy_bits("LXD")


def test_vehicle_boxes_cover_their_class(small_scenes):
    for scene in small_scenes:
        for vehicle in scene.vehicles:
            x1, y1, x2, y2 = vehicle.box_xyxy
            assert 0 <= x1 < x2 <= SMALL[1] and 0 <= y1 < y2 <= SMALL[0]


def test_crop_shifts_and_clips_plate_boxes(full_scenes):
    scene = next(s for s in full_scenes if len(s.plates) >= 3)
    box = (200, 150, 712, 406)
    cropped = crop_scene(scene, box)
    assert cropped.image.shape == (256, 512, 3)
    for k, plate in enumerate(cropped.plates):
        original = next(p for p in scene.plates if p.text == plate.text)
        ox1, oy1, ox2, oy2 = original.box_xyxy
        assert plate.box_xyxy == (max(ox1, 200) - 200, max(oy1, 150) - 150, min(ox2, 712) - 200, min(oy2, 406) - 150)
        visible = cropped.plate_mask == k + 1
        assert np.all(cropped.labels[visible] == cropped.vehicles[plate.vehicle_index].train_id)
        full_visible = (scene.plate_mask == scene.plates.index(original) + 1).sum()
        assert plate.visible_fraction == pytest.approx(original.visible_fraction * visible.sum() / full_visible)
    inside = [p for p in scene.plates if p.box_xyxy[0] < 712 and p.box_xyxy[2] > 200
              and p.box_xyxy[1] < 406 and p.box_xyxy[3] > 150]
    assert len(cropped.plates) == len(inside)


def test_flip_mirrors_boxes_and_marks_plates(full_scenes):
    scene = full_scenes[0]
    flipped = flip_scene(scene)
    width = scene.labels.shape[1]
    for plate, original in zip(flipped.plates, scene.plates):
        x1, y1, x2, y2 = original.box_xyxy
        assert plate.box_xyxy == (width - x2, y1, width - x1, y2) and plate.mirrored
        fx1, _, fx2, _ = plate.box_xyxy
        assert np.array_equal(flipped.image[y1:y2, fx1:fx2], scene.image[y1:y2, x1:x2][:, ::-1])
    for vehicle, original in zip(flipped.vehicles, scene.vehicles):
        assert vehicle.box_xyxy == (width - original.box_xyxy[2], original.box_xyxy[1], width - original.box_xyxy[0],
                                    original.box_xyxy[3])


def test_dataset_items_are_reproducible_tensors():
    data = SceneDataset("synthetic", "train", 2, size=(64, 128), crop=(32, 48), flip=True, seed=1)
    item = data[1]
    assert item["image"].shape == (3, 32, 48) and item["image"].dtype == torch.float32
    assert item["labels"].shape == (32, 48) and item["labels"].dtype == torch.int64 and item["index"] == 1
    assert torch.equal(item["image"], data[1]["image"])
    assert data.scenes[1].image.shape == (64, 128, 3) and len(data.scenes) == 2
    sample = data.sample(1, torch.Generator().manual_seed(0))
    assert sample.labels.shape == (32, 48)
    data.set_epoch(1)
    assert any(not torch.equal(data[i]["image"], SceneDataset("synthetic", "train", 2, size=(64, 128), crop=(32, 48),
                                                               flip=True, seed=1)[i]["image"]) for i in range(2))
    with pytest.raises(ValueError, match="crop"):
        SceneDataset("synthetic", "train", 2, size=(64, 128), crop=(65, 10))


@pytest.mark.parametrize(("bad", "suggestion"), [("synthetc", "synthetic"), ("photo", "photos")])
def test_unknown_scene_set_suggests_a_close_match(bad, suggestion):
    with pytest.raises(ValueError, match=f"unknown scene set '{bad}'.*Did you mean '{suggestion}'"):
        load_scenes(bad, "train", 1)


def test_unknown_split_suggests_and_a_missing_cityscapes_root_is_named():
    with pytest.raises(ValueError, match="unknown split 'tset'.*'test'"):
        load_scenes("synthetic", "tset", 1)
    with pytest.raises(FileNotFoundError, match="not an existing folder"):
        load_scenes("cityscapes:/data/cityscapes", "train", 1)
    assert set(SCENE_SETS) >= {"synthetic", "photos"} and all(SCENE_SETS.values())


def test_photos_load_with_shape_range_and_cycle_with_new_crops():
    n = len(PHOTO_SPLITS["test"]) + 1
    scenes = load_scenes("photos", "test", n, size=(96, 160))
    for scene in scenes:
        assert scene.image.shape == (96, 160, 3) and scene.image.dtype == np.float32
        assert 0.0 <= scene.image.min() < 0.2 and 0.8 < scene.image.max() <= 1.0
        assert np.all(scene.labels == 255) and scene.plates == [] and scene.vehicles == []
    assert scenes[0].name.endswith(PHOTO_SPLITS["test"][0]) and scenes[-1].name.endswith(PHOTO_SPLITS["test"][0])
    assert not np.array_equal(scenes[0].image, scenes[-1].image)
    names = [set(v) for v in PHOTO_SPLITS.values()]
    assert all(not a & b for a, b in itertools.combinations(names, 2))
