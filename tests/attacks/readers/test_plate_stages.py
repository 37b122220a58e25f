"""Each stage of the plate attack alone, on fixtures with known answers (attacks/readers/plates/)."""

from __future__ import annotations

import socket

import numpy as np
import pytest

from attacks.readers.plates.detect_craft import detect_craft, magnification
from attacks.readers.plates.detect_opencv import detect_opencv
from attacks.readers.plates.easyocr_models import load_easyocr, model_dir
from attacks.readers.plates.ocr import apply_format, normalise, prepare_crop, read_plate, read_plates
from attacks.readers.plates.vehicles import expand_box, oracle_vehicles, segmentation_vehicles
from benchmark.results.plate_scoring import iou
from benchmark.scenes import render_plate

PLATE_TEXT = "KD482MX"


def _no_network(*args, **kwargs):
    raise OSError("network access attempted during an offline test")


@pytest.fixture(scope="module")
def ocr():
    with pytest.MonkeyPatch.context() as mp:
        mp.setattr(socket.socket, "connect", _no_network)
        yield load_easyocr(detector=True)


def vehicle_with_plate(plate_w: int = 90, at_border: bool = False) -> tuple[np.ndarray, tuple[int, int, int, int]]:
    """A grey car body (200 x 120 px) on asphalt with one light plate; returns (crop RGB uint8, plate box)."""
    crop = np.full((140, 240, 3), 90, np.uint8)
    crop[10:130, 20:220] = (150, 40, 40)
    crop[30:60, 50:190] = (60, 70, 80)  # rear window
    plate_h = round(plate_w * 0.11 / 0.52)
    x0 = 240 - plate_w if at_border else 120 - plate_w // 2
    y0 = 95
    crop[y0:y0 + plate_h, x0:x0 + plate_w] = np.asarray(render_plate(PLATE_TEXT, (plate_w, plate_h)))
    return crop, (x0, y0, x0 + plate_w, y0 + plate_h)


def test_models_ship_offline():
    folder = model_dir()
    assert (folder / "craft_mlt_25k.pth").stat().st_size > 1e6
    assert (folder / "english_g2.pth").stat().st_size > 1e6


def test_segmentation_vehicles_finds_components_of_car_truck_bus_only():
    labels = np.full((60, 100), 0, np.uint8)
    labels[10:30, 5:40] = 13  # car
    labels[35:55, 50:95] = 15  # bus
    labels[5:15, 60:70] = 11  # person: not a vehicle
    labels[50, 10] = 14  # one-pixel truck: noise
    boxes = segmentation_vehicles(labels, min_area_px=4)
    assert boxes == [(50, 35, 95, 55), (5, 10, 40, 30)]  # largest first, x1 / y1 exclusive
    assert segmentation_vehicles(np.zeros((8, 8), np.uint8)) == []
    with pytest.raises(ValueError, match="shape"):
        segmentation_vehicles(np.zeros((2, 8, 8), np.uint8))


def test_oracle_vehicles_and_margin_are_clipped_to_the_image():
    assert oracle_vehicles([(-5.5, 2.2, 30.1, 70.0), (200, 0, 210, 5)], (50, 100)) == [(0, 2, 31, 50)]
    assert expand_box((0, 10, 20, 30), 0.5, (40, 25)) == (0, 0, 25, 40)
    assert expand_box((10, 10, 20, 20), 0.1, (100, 100)) == (9, 9, 21, 21)


def test_opencv_detector_finds_the_plate():
    crop, truth = vehicle_with_plate()
    boxes = detect_opencv(crop)
    assert boxes
    x0, y0, x1, y1 = boxes[0]  # the plate, or the text on it: inside the plate, most of its width
    assert x0 >= truth[0] - 2 and y0 >= truth[1] - 2 and x1 <= truth[2] + 2 and y1 <= truth[3] + 2
    assert x1 - x0 >= 0.5 * (truth[2] - truth[0]) and iou(boxes[0], truth) >= 0.3


@pytest.mark.parametrize("detector", ["opencv", "craft"])
def test_detectors_handle_empty_plain_and_border_crops(detector, ocr):
    detect = detect_opencv if detector == "opencv" else (lambda c: detect_craft(ocr, c))
    assert detect(np.zeros((0, 0, 3), np.uint8)) == []
    assert detect(np.zeros((3, 50, 3), np.uint8)) == []
    no_plate = np.full((120, 200, 3), (150, 40, 40), np.uint8)
    assert detect(no_plate) == []
    crop, truth = vehicle_with_plate(at_border=True)
    boxes = detect(crop)
    assert all(0 <= b[0] < b[2] <= crop.shape[1] and 0 <= b[1] < b[3] <= crop.shape[0] for b in boxes)
    assert any(iou(b, truth) >= 0.3 for b in boxes)


def test_craft_detector_finds_the_plate_text(ocr):
    crop, truth = vehicle_with_plate()
    boxes = detect_craft(ocr, crop)
    assert boxes and iou(boxes[0], truth) >= 0.5
    assert magnification(64) == 4.0 and magnification(64, 256, 3.0) == 3.0 and magnification(1000) == 1.0 and magnification(128, 256) == 2.0


def test_ocr_reads_a_rendered_plate_and_trims_border_and_band(ocr):
    plate = np.asarray(render_plate(PLATE_TEXT, (160, 34), eu_band=True))
    prepared = prepare_crop(plate)
    assert prepared.ndim == 2 and prepared.shape[0] <= 64 and prepared.shape[1] < 160 * 64 / 34
    assert read_plate(ocr, plate, "LLDDDLL").text == PLATE_TEXT
    yellow = np.asarray(render_plate("ZB190OQ", (160, 34), background=(240, 210, 40)))
    results = read_plates(ocr, [plate, np.zeros((0, 5, 3), np.uint8), yellow], "LLDDDLL")
    assert [r.text for r in results] == [PLATE_TEXT, "", "ZB190OQ"]
    assert results[1].score == 0.0 and 0.0 < results[0].score <= 1.0


def test_ocr_of_a_flat_crop_reads_nothing_plate_like(ocr):
    assert len(read_plate(ocr, np.full((20, 90, 3), 200, np.uint8)).text) < 3


def test_text_normalisation_and_plate_syntax():
    assert normalise("ab-12 c\u00e9") == "AB12C"
    assert apply_format("0L254VS", "LLDDDLL") == "OL254VS"
    assert apply_format("SEB94NH", "LLDDDLL") == "SE894NH"
    assert apply_format("SEB94NH", None) == "SEB94NH"
    assert apply_format("SEB94", "LLDDDLL") == "SEB94"
