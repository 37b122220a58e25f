"""Plate windows: the window's sensor simulation equals the full frame's inside the window; the
quick profile's plate set holds >= 200 readable plates per seed."""

from __future__ import annotations

import numpy as np
import pytest
import scipy.stats
import torch

import lenses
from benchmark.runner.evaluation import shape_batches
from benchmark.results.plate_scoring import WIDTH_BINS_PX, readable, scored
from benchmark.store.profiles import get_profile
from benchmark.runner.config import RunConfig
from benchmark.scenes import load_scene
from benchmark.scenes.windows import PlateWindow, WidthQuota, plate_windows, window_box, window_scene
from benchmark.runner.sensing import noise_key, positional_normal, sense_windows, simulation_box
from benchmark.runner.tasks import plate_set

FRAME_HW = (128, 256)
# Interior (odd corner), on the top-left corner, on the bottom-right corner, and the whole frame.
WINDOWS = ((37, 21, 141, 93), (0, 0, 64, 48), (171, 77, 256, 128), (0, 0, 256, 128))
ONE_LEVEL = 1 / 1023  # a 10-bit ADC step


@pytest.fixture(scope="module")
def frame():
    return load_scene("synthetic", "val", 0, FRAME_HW, 0)


def _sensed(lens, frame, boxes):
    return sense_windows(lens, [frame], [PlateWindow(0, b, 0) for b in boxes], seed=3, device="cpu")


def test_positional_noise_is_standard_normal_and_independent_of_the_window():
    key = 12345
    full = positional_normal(key, range(0, 300), range(0, 400))
    assert torch.equal(positional_normal(key, range(101, 157), range(33, 250)), full[101:157, 33:250])
    values = full.double().numpy().ravel()
    assert scipy.stats.kstest(values, "norm").pvalue > 1e-3
    assert abs(np.corrcoef(full[:, :-1].ravel(), full[:, 1:].ravel())[0, 1]) < 0.02  # neighbours independent
    assert not torch.equal(positional_normal(key + 1, range(0, 8), range(0, 8)), full[:8, :8])


def test_injected_noise_is_the_sensor_noise():
    """Sensor(eps=the generator's own draw) is bit-equal to Sensor(generator): eps replaces the draw."""
    lens = lenses.load("ideal")
    irradiance = torch.rand(2, 3, 16, 24, generator=torch.Generator().manual_seed(0))
    eps = torch.randn(2, 1, 16, 24, generator=torch.Generator().manual_seed(7))
    assert torch.equal(lens.sensor(irradiance, eps=eps), lens.sensor(irradiance, generator=torch.Generator().manual_seed(7)))
    with pytest.raises(ValueError, match="raw image's shape"):
        lens.sensor(irradiance, eps=eps[:, :, :8])


def test_window_equals_full_frame_bit_for_bit_without_blur(frame):
    """sensor-only (a delta PSF: no convolution rounding): mosaic phase, noise, clipping, quantization
    and demosaic of every window equal the full frame's, bit for bit."""
    lens = lenses.load("sensor-only")
    *windows, full = _sensed(lens, frame, WINDOWS)
    for (x0, y0, x1, y1), window in zip(WINDOWS, windows):
        assert torch.equal(window, full[:, y0:y1, x0:x1]), (x0, y0)


@pytest.mark.parametrize("name", ["ideal", "defocus"])  # direct convolution and FFT (K > 15)
def test_window_equals_full_frame_inside_the_window(name, frame):
    """With a PSF: the irradiance of the simulated region equals the full frame's to float rounding,
    so the sensor images agree except where rounding moved a value across a quantization step."""
    lens = lenses.load(name)
    k = lens.psf().shape[-1]
    image = torch.from_numpy(frame.image).permute(2, 0, 1)[None]
    with torch.no_grad():
        irradiance = lens.irradiance(image)
        for box in WINDOWS[:3]:
            sx0, sy0, sx1, sy1 = simulation_box(box, FRAME_HW, k // 2 + 2)
            region = lens.irradiance(image[..., sy0:sy1, sx0:sx1])
            x0, y0, x1, y1 = box
            inside = region[..., y0 - sy0:y1 - sy0, x0 - sx0:x1 - sx0]
            torch.testing.assert_close(inside, irradiance[..., y0:y1, x0:x1], rtol=0, atol=1e-5)
    *windows, full = _sensed(lens, frame, WINDOWS)
    for (x0, y0, x1, y1), window in zip(WINDOWS, windows):
        diff = (window - full[:, y0:y1, x0:x1]).abs()
        assert float(diff.max()) <= ONE_LEVEL * 1.001
        # A flipped ADC level is rare (the irradiance moved by ~1e-7 of a level's width around a
        # rounding edge) and the demosaic spreads each flip over up to 9 values of a 3 x 3 block.
        assert float((diff > 0).double().mean()) < 1e-2


def test_a_window_without_halo_differs(frame):
    """The injected fault: simulating only the window itself (no halo) changes pixels inside it."""
    lens = lenses.load("defocus")
    image = torch.from_numpy(frame.image).permute(2, 0, 1)[None]
    x0, y0, x1, y1 = WINDOWS[0]
    with torch.no_grad():
        bare = lens.irradiance(image[..., y0:y1, x0:x1])
        full = lens.irradiance(image)[..., y0:y1, x0:x1]
    assert float((bare - full).abs().max()) > 1e-3


def test_window_box_holds_its_target_inside_the_frame():
    rng = np.random.default_rng(0)
    for _ in range(200):
        x0, y0 = int(rng.integers(0, 1000)), int(rng.integers(0, 500))
        target = (x0, y0, min(x0 + int(rng.integers(1, 600)), 1024), min(y0 + int(rng.integers(1, 400)), 512))
        if target[2] <= target[0] or target[3] <= target[1]:
            continue
        box = window_box(target, (512, 1024), (256, 256))
        w, h = box[2] - box[0], box[3] - box[1]
        assert 0 <= box[0] and 0 <= box[1] and box[2] <= 1024 and box[3] <= 512
        assert w >= min(256, 1024) and h >= 256
        assert w % 64 == 0 and h % 64 == 0
        if (target[2] - target[0]) * 1.5 <= 1024 and (target[3] - target[1]) * 1.5 <= 512:
            assert box[0] <= target[0] and box[1] <= target[1] and box[2] >= target[2] and box[3] >= target[3]


def test_window_scene_keeps_the_plate_and_its_vehicle():
    frames = [load_scene("synthetic", "val", i, (512, 1024), 0) for i in range(3)]
    windows = plate_windows(frames, readable, (256, 256))
    assert len(windows) >= 2
    for w in windows:
        frame = frames[w.frame]
        scene = window_scene(frame, w)
        (plate,) = scene.plates
        original = frame.plates[w.plate]
        assert plate.text == original.text and readable(plate)
        x0, y0 = w.box_xyxy[:2]
        px0, py0, px1, py1 = plate.box_xyxy
        assert np.array_equal(scene.image[py0:py1, px0:px1], frame.image[py0 + y0:py1 + y0, px0 + x0:px1 + x0])
        assert scene.vehicles[plate.vehicle_index].train_id == frame.vehicles[original.vehicle_index].train_id


def test_shape_batches_keep_order_and_group_equal_shapes():
    images = [torch.zeros(3, h, 8) for h in (4, 4, 4, 6, 4, 4)]
    got = [(start, tuple(b.shape)) for start, b in shape_batches(images, 2)]
    assert got == [(0, (2, 3, 4, 8)), (2, (1, 3, 4, 8)), (3, (1, 3, 6, 8)), (4, (2, 3, 4, 8))]


@pytest.mark.slow
def test_quick_plate_set_fills_every_width_bin_from_8_to_64_px(tmp_path):
    """Counted from the scene generator alone (no lens): the quick profile's plate set of seed 0 holds
    50 scored plates in each width bin from 8 to 64 px, and no wider bin more than 25."""
    cfg = RunConfig(["ideal"], None, "synthetic", get_profile("quick"), [0], cache_dir=tmp_path)
    plates = plate_set(cfg, 0, None)
    assert plates is not None and all(scored(s.plates[0]) for s in plates.scenes)
    widths = np.array([s.plates[0].box_xyxy[2] - s.plates[0].box_xyxy[0] for s in plates.scenes])
    counts = np.histogram(widths, [*WIDTH_BINS_PX, np.inf])[0]
    assert all(c == 50 for low, c in zip(WIDTH_BINS_PX, counts) if low < 64), counts
    assert all(c <= 25 for low, c in zip(WIDTH_BINS_PX, counts) if low >= 64) and widths.min() >= 8
    assert len({s.name for s in plates.scenes}) == len(plates.scenes)
    assert plates.n_frames <= get_profile("quick").plate_frames
    assert all(t.shape[1:] == s.image.shape[:2] for t, s in zip(plates.sharp, plates.scenes))
    assert noise_key(0, load_scene("synthetic", "val", 0, (8, 16), 0)) != noise_key(1, load_scene(
        "synthetic", "val", 0, (8, 16), 0))


def test_width_quota_takes_plates_until_the_required_bins_are_full():
    quota = WidthQuota((8, 16, 32, 64), per_bin=(2, 2, 2, 2), required_below_px=32)
    assert not quota.take(7)                      # below the first edge: never taken
    assert [quota.take(w) for w in (8, 15, 9)] == [True, True, False]  # bin [8, 16) holds 2
    assert not quota.full
    assert quota.take(500) and quota.take(64) and not quota.take(70)    # the open top bin
    assert [quota.take(w) for w in (16, 31)] == [True, True] and quota.full  # [32, 64) is not required
    assert quota.counts == [2, 2, 0, 2]
    with pytest.raises(ValueError, match="increasing"):
        WidthQuota((16, 8), (1, 1), 16)
    with pytest.raises(ValueError, match="one quota per width bin"):
        WidthQuota((8, 16), (1,), 16)
