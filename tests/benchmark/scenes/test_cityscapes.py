"""``cityscapes:PATH`` on a tiny tree of the official layout: ids, order, resizing, vehicles, plates, errors."""

from __future__ import annotations

import json
import logging
from pathlib import Path

import numpy as np
import pytest
from cityscapesscripts.helpers.labels import id2label
from PIL import Image

from benchmark.scenes import SceneDataset, Vehicle, load_scene, load_scenes, scene_seed
from benchmark.scenes.cityscapes import CityscapesFormatError, CityscapesNotFoundError

H, W = 32, 64
CITIES = ("frankfurt", "lindau")
STEMS = [f"{city}_000000_{frame:06d}" for city in CITIES for frame in (19, 576)]
ROAD, SKY, CAR, TRUCK, UNLABELED = 7, 23, 26, 27, 0
CAR_A = (4, 10, 14, 20)   # x0, y0, x1, y1 in native pixels
CAR_B = (30, 12, 40, 24)
TRUCK_BOX = (48, 4, 60, 16)


def _label_ids() -> np.ndarray:
    ids = np.full((H, W), SKY, dtype=np.uint8)
    ids[H // 2:] = ROAD
    ids[:2, :2] = UNLABELED
    for label_id, (x0, y0, x1, y1) in ((CAR, CAR_A), (CAR, CAR_B), (TRUCK, TRUCK_BOX)):
        ids[y0:y1, x0:x1] = label_id
    return ids


def _image(k: int) -> np.ndarray:
    ramp = 3 * np.arange(W)[None, :, None]  # exactly linear in x, so resampling has a closed form
    return np.broadcast_to(ramp + np.array([0, 1, 2]) + k, (H, W, 3)).astype(np.uint8)


def _save(array: np.ndarray, path: Path) -> None:
    path.parent.mkdir(parents=True, exist_ok=True)
    Image.fromarray(array).save(path)


def _paths(root: Path, split: str, stem: str) -> tuple[Path, Path, Path]:
    city = stem.split("_")[0]
    gt = root / "gtFine" / split / city
    return (root / "leftImg8bit" / split / city / f"{stem}_leftImg8bit.png", gt / f"{stem}_gtFine_labelIds.png",
            gt / f"{stem}_gtFine_instanceIds.png")


@pytest.fixture
def tree(tmp_path: Path) -> Path:
    """2 cities x 2 frames of val, written in reverse order so that sorting is what orders them."""
    for k, stem in reversed(list(enumerate(STEMS))):
        image, labels, _ = _paths(tmp_path, "val", stem)
        _save(_image(k), image)
        _save(_label_ids(), labels)
    return tmp_path


def _plates(root: Path, split: str, data: object) -> None:
    (root / "plates").mkdir(exist_ok=True)
    (root / "plates" / f"{split}.json").write_text(json.dumps(data), encoding="utf-8")


def _load(root: Path, split: str = "val", n: int = 4, size: tuple[int, int] = (H, W), seed: int = 0):
    return load_scenes("cityscapes:" + str(root), split, n, size, seed)


def test_label_ids_map_to_train_ids_as_cityscapesscripts_says(tree):
    scene = _load(tree, n=1)[0]
    ids = _label_ids()
    assert scene.labels.dtype == np.uint8 and scene.labels.shape == (H, W)
    assert scene.labels[H - 1, 0] == 0 and scene.labels[CAR_A[1], CAR_A[0]] == 13 and scene.labels[0, 0] == 255
    expected = np.vectorize(lambda i: id2label[i].trainId if id2label[i].trainId not in (-1, 255) else 255)(ids)
    np.testing.assert_array_equal(scene.labels, expected)


def test_scenes_follow_sorted_file_names_and_native_images_are_exact(tree):
    scenes = _load(tree, seed=3)
    assert [s.name.rsplit("-", 1)[1] for s in scenes] == sorted(STEMS)
    assert [s.seed for s in scenes] == [scene_seed("val", 3, i) for i in range(4)]
    for k, scene in enumerate(scenes):
        assert scene.image.dtype == np.float32 and scene.image.shape == (H, W, 3)
        np.testing.assert_array_equal(scene.image, _image(k).astype(np.float32) / 255)
    other_seed = _load(tree, seed=4)
    assert all(np.array_equal(a.image, b.image) and a.vehicles == b.vehicles for a, b in zip(scenes, other_seed))


def test_n_beyond_the_split_returns_what_exists_with_a_warning(tree, caplog):
    with caplog.at_level(logging.WARNING):
        scenes = _load(tree, n=10)
    assert len(scenes) == 4 and "has 4 images" in caplog.text
    with pytest.raises(IndexError, match="has 4 images"):
        load_scene("cityscapes:" + str(tree), "val", 4, (H, W))


def test_downscaling_averages_the_image_and_takes_labels_nearest(tree):
    scene = _load(tree, n=1, size=(H // 2, W // 2))[0]
    assert scene.image.shape == (H // 2, W // 2, 3) and scene.labels.shape == (H // 2, W // 2)
    # A linear ramp resampled with a symmetric filter keeps its value at each output pixel centre.
    native = _image(0)[0, :, 0].astype(np.float64) / 255
    centres = (np.arange(W // 2) + 0.5) * 2 - 0.5
    expected = np.interp(centres, np.arange(W), native)
    np.testing.assert_allclose(scene.image[0, 2:-2, 0], expected[2:-2], atol=1e-5)
    assert set(np.unique(scene.labels)) <= {0, 2, 10, 13, 14, 255}
    ids = _label_ids()
    train = {ROAD: 0, SKY: 10, CAR: 13, TRUCK: 14, UNLABELED: 255}
    for y, x in np.ndindex(scene.labels.shape):
        assert scene.labels[y, x] in {train[i] for i in ids[2 * y:2 * y + 2, 2 * x:2 * x + 2].ravel()}


def test_upscaling_by_two_repeats_labels_and_scales_boxes(tree):
    scene = _load(tree, n=1, size=(2 * H, 2 * W))[0]
    native = _load(tree, n=1)[0]
    np.testing.assert_array_equal(scene.labels, np.kron(native.labels, np.ones((2, 2), dtype=np.uint8)))
    assert [v.box_xyxy for v in scene.vehicles] == [tuple(2 * c for c in v.box_xyxy) for v in native.vehicles]


def test_vehicles_are_connected_components_of_vehicle_classes(tree):
    scene = _load(tree, n=1)[0]
    assert scene.vehicles == [Vehicle(13, CAR_A), Vehicle(13, CAR_B), Vehicle(14, TRUCK_BOX)]
    small = _load(tree, n=1, size=(H // 2, W // 2))[0]
    assert [v.box_xyxy for v in small.vehicles] == [(2, 5, 7, 10), (15, 6, 20, 12), (24, 2, 30, 8)]


def test_instance_ids_give_one_box_per_instance(tree):
    ids = _label_ids()
    ids[CAR_A[1]:CAR_A[3], CAR_A[2]:CAR_B[0]] = CAR  # join the two cars into one component
    instances = ids.astype(np.int32)  # pixels outside instances keep their label id (the truck: a crowd region)
    column = np.arange(W)[None, :]
    instances[(ids == CAR) & (column < 20)] = CAR * 1000
    instances[(ids == CAR) & (column >= 20)] = CAR * 1000 + 1
    instances[0:2, 40:44] = 24 * 1000 + 3  # a person instance is not a vehicle
    _, labels, instance_path = _paths(tree, "val", STEMS[0])
    _save(ids, labels)
    _save(instances.astype(np.uint16), instance_path)
    left_of_join = (CAR_A[0], CAR_A[1], 20, CAR_A[3])
    right_of_join = (20, CAR_A[1], CAR_B[2], CAR_B[3])
    assert _load(tree, n=1)[0].vehicles == [Vehicle(13, left_of_join), Vehicle(13, right_of_join)]
    instance_path.unlink()
    assert len(_load(tree, n=1)[0].vehicles) == 2  # one joined car component and the truck


def test_plates_are_read_normalised_scaled_and_given_to_the_vehicle_under_their_centre(tree):
    _plates(tree, "val", {
        STEMS[0]: [{"text": "F-ab 12", "box_xyxy": [6, 16, 12, 18], "visible_fraction": 0.5},
                   {"text": "XY9", "box_xyxy": [20.5, 2, 25.5, 4]},
                   {"text": "TR1", "box_xyxy": [50, 12, 54, 14]}],
        "munster_000000_000000": [],
    })
    native, second = _load(tree, n=2)
    assert [(p.text, p.box_xyxy, p.vehicle_index, p.visible_fraction) for p in native.plates] == [
        ("FAB12", (6, 16, 12, 18), 0, 0.5), ("XY9", (20, 2, 26, 4), -1, 1.0), ("TR1", (50, 12, 54, 14), 2, 1.0)]
    assert second.plates == []
    small = _load(tree, n=1, size=(H // 2, W // 2))[0]
    assert [(p.box_xyxy, p.vehicle_index) for p in small.plates] == [((3, 8, 6, 9), 0), ((10, 1, 13, 2), -1),
                                                                      ((25, 6, 27, 7), 2)]
    assert not any(p.mirrored for p in small.plates) and small.plate_mask is None


def test_test_split_without_labels_is_all_ignore(tmp_path):
    image, _, _ = _paths(tmp_path, "test", "berlin_000000_000019")
    _save(_image(0), image)
    scene = _load(tmp_path, "test", 1, size=(16, 32))[0]
    assert (scene.labels == 255).all() and scene.labels.shape == (16, 32) and scene.vehicles == []


def test_through_the_public_api_and_the_torch_dataset(tree):
    size = (16, 32)
    scenes = load_scenes("cityscapes:" + str(tree), "val", 2, size)
    assert len(scenes) == 2 and scenes[0].image.shape == (*size, 3)
    item = SceneDataset("cityscapes:" + str(tree), "val", 2, size=size, crop=(8, 8), flip=True)[1]
    assert item["image"].shape == (3, 8, 8) and item["labels"].shape == (8, 8)


def test_missing_root_split_and_label_files_are_named(tree):
    with pytest.raises(CityscapesNotFoundError, match="nowhere.*not an existing folder.*leftImg8bit"):
        _load(tree / "nowhere")
    with pytest.raises(FileNotFoundError, match="has no path"):
        load_scenes("cityscapes:", "val", 1)
    with pytest.raises(CityscapesNotFoundError, match=r"leftImg8bit/train.*does not exist.*splits present: val"):
        _load(tree, "train")
    _, labels, _ = _paths(tree, "val", STEMS[1])
    labels.unlink()
    _load(tree, n=1)  # only the image that lacks labels fails
    with pytest.raises(CityscapesNotFoundError, match=f"has no label file.*{STEMS[1]}_gtFine_labelIds.png.*'test'"):
        _load(tree, n=2)


def test_undecodable_png_is_named(tree):
    image, _, _ = _paths(tree, "val", STEMS[0])
    image.write_bytes(image.read_bytes()[:60])
    with pytest.raises(CityscapesFormatError, match=f"cannot decode.*{STEMS[0]}_leftImg8bit.png"):
        _load(tree, n=1)


@pytest.mark.parametrize(("labels", "message"), [
    (np.full((H, W), 200, dtype=np.uint8), r"label ids \[200\] unknown to cityscapesscripts; valid ids are -1..33"),
    (np.zeros((H, W, 3), dtype=np.uint8), "mode 'RGB'; expected a single-channel"),
    (np.zeros((H, W // 2), dtype=np.uint8), f"is {H}x{W // 2} but its image .* is {H}x{W}"),
])
def test_bad_label_files_are_named(tree, labels, message):
    _, path, _ = _paths(tree, "val", STEMS[0])
    _save(labels, path)
    with pytest.raises(CityscapesFormatError, match=f"{STEMS[0]}_gtFine_labelIds.png.*{message}"):
        _load(tree, n=1)


@pytest.mark.parametrize(("content", "message"), [
    ("{not json", "is not valid JSON"),
    ([], "holds a list, not an object"),
    ({STEMS[0]: {"text": "A1"}}, "a list of plates is needed"),
    ({STEMS[0]: [{"text": "A1"}]}, r"missing keys \['box_xyxy'\]"),
    ({STEMS[0]: [{"text": "A1", "box_xyxy": [0, 0, 1, 1], "colour": "white"}]}, r"unknown keys \['colour'\]"),
    ({STEMS[0]: [{"text": "A.1", "box_xyxy": [0, 0, 1, 1]}]}, "text 'A.1' must be letters and digits"),
    ({STEMS[0]: [{"text": "A1", "box_xyxy": [0, 0, 1]}]}, "must be four numbers"),
    ({STEMS[0]: [{"text": "A1", "box_xyxy": [0, 0, 1, 1], "visible_fraction": 2}]}, r"must be a number in \[0, 1\]"),
    ({STEMS[0]: [{"text": "A1", "box_xyxy": [0, 0, W + 1, 1]}]}, f"0 <= x0 < x1 <= {W}"),
    ({STEMS[0]: [{"text": "A1", "box_xyxy": [5, 5, 5, 6]}]}, "0 <= x0 < x1"),
])
def test_malformed_plates_files_are_named(tree, content, message):
    (tree / "plates").mkdir()
    path = tree / "plates" / "val.json"
    path.write_text(content if isinstance(content, str) else json.dumps(content), encoding="utf-8")
    with pytest.raises(CityscapesFormatError, match=f"plates file .*val.json.*{message}"):
        _load(tree, n=1)
