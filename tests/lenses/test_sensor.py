import cv2
import numpy as np
import pytest
import skimage.data
import torch

from lenses.sensor import Sensor, demosaic_bilinear, mosaic
from lenses.spec import SensorSpec


def test_opencv_is_the_headless_build_with_bayer_demosaic():
    # One cv2 distribution on purpose (EasyOCR's opencv-python-headless): check we got what we use.
    assert hasattr(cv2, "COLOR_BayerBG2RGB")
    from importlib.metadata import distribution, PackageNotFoundError
    names = []
    for dist in ("opencv-python", "opencv-contrib-python", "opencv-python-headless", "opencv-contrib-python-headless"):
        try:
            distribution(dist)
            names.append(dist)
        except PackageNotFoundError:
            pass
    assert names == ["opencv-python-headless"], f"conflicting OpenCV wheels installed: {names}"


def test_bilinear_demosaic_matches_opencv():
    img = skimage.data.astronaut()[100:228, 60:252].astype(np.float32)
    raw = mosaic(torch.from_numpy(img).permute(2, 0, 1)[None])
    ours = demosaic_bilinear(raw)[0].permute(1, 2, 0).numpy()
    # OpenCV names Bayer patterns after the second row: our RGGB (R at (0,0)) is its "BG".
    theirs = cv2.cvtColor(raw[0, 0].numpy().astype(np.uint8), cv2.COLOR_BayerBG2RGB).astype(np.float32)
    interior = (slice(2, -2), slice(2, -2))
    assert np.abs(ours[interior] - theirs[interior]).max() <= 0.5  # OpenCV rounds to uint8


def test_mosaic_keeps_one_channel_per_pixel_in_rggb_order():
    rgb = torch.stack([torch.full((4, 4), float(c + 1)) for c in range(3)])[None]
    raw = mosaic(rgb)[0, 0]
    assert raw.tolist() == [[1, 2, 1, 2], [2, 3, 2, 3], [1, 2, 1, 2], [2, 3, 2, 3]]


def test_demosaic_is_exact_on_constant_colour():
    rgb = torch.tensor([0.2, 0.5, 0.7])[None, :, None, None].expand(1, 3, 16, 20)
    torch.testing.assert_close(demosaic_bilinear(mosaic(rgb)), rgb)


def test_noise_mean_and_variance_follow_poisson_gaussian_theory():
    spec = SensorSpec()
    sensor = Sensor(spec, aperture_diameter_mm=5.0)
    level = 0.3
    x = torch.full((1, 3, 256, 256), level)
    e = sensor.raw_electrons(x, generator=torch.Generator().manual_seed(0))[0, 0]
    masks = [(slice(0, None, 2), slice(0, None, 2)), (slice(0, None, 2), slice(1, None, 2)),
             (slice(1, None, 2), slice(1, None, 2))]
    for ch, (rows, cols) in enumerate(masks):
        mu = level * spec.white_level_photons * spec.quantum_efficiency[ch]
        samples = e[rows, cols].double()
        n = samples.numel()
        var = mu + spec.read_noise_e**2
        assert float(samples.mean()) == pytest.approx(mu, abs=4 * (var / n) ** 0.5)
        assert float(samples.var()) == pytest.approx(var, rel=4 * (2 / n) ** 0.5)


def test_quantized_output_mean_and_levels():
    spec = SensorSpec()
    sensor = Sensor(spec, aperture_diameter_mm=5.0)
    y = sensor(torch.full((1, 3, 64, 64), 0.5), generator=torch.Generator().manual_seed(1))
    levels = mosaic(y) * (2**spec.adc_bits - 1)  # each pixel's own channel is its raw ADC value
    torch.testing.assert_close(levels, levels.round(), atol=1e-3, rtol=0)
    torch.testing.assert_close(y.mean(dim=(0, 2, 3)), 0.5 * sensor.gain(), atol=2e-3, rtol=0)


def test_aperture_area_scales_intensity():
    half = Sensor(SensorSpec(), aperture_diameter_mm=2.5)
    torch.testing.assert_close(half.gain(), Sensor(SensorSpec(), 5.0).gain() / 4)


def test_full_well_clips():
    sensor = Sensor(SensorSpec(), aperture_diameter_mm=5.0)
    y = sensor(torch.full((1, 3, 8, 8), 10.0), generator=torch.Generator().manual_seed(0))
    assert float(y.max()) == 1.0


def test_same_seed_same_image_and_straight_through_gradient():
    sensor = Sensor(SensorSpec(), aperture_diameter_mm=5.0)
    x = torch.rand(2, 3, 32, 32, requires_grad=True)
    a = sensor(x, generator=torch.Generator().manual_seed(5))
    b = sensor(x, generator=torch.Generator().manual_seed(5))
    c = sensor(x, generator=torch.Generator().manual_seed(6))
    assert torch.equal(a, b) and not torch.equal(a, c)
    a.sum().backward()
    assert x.grad is not None and float(x.grad.abs().sum()) > 0


def test_quantize_without_a_graph_is_the_straight_through_value_bit_for_bit():
    from lenses.sensor import quantize_ste
    x = torch.cat([torch.rand(100_000, generator=torch.Generator().manual_seed(0)) * 1023,
                   torch.arange(0, 1024, 0.5), torch.tensor([0.0, 0.49999997, 0.5, 1.5, 2.5, 1022.5])])
    straight_through = x + (torch.round(x) - x)
    assert torch.equal(quantize_ste(x), straight_through)
    y = x.clone().requires_grad_(True)
    q = quantize_ste(y)
    assert torch.equal(q.detach(), straight_through)
    q.sum().backward()
    assert torch.equal(y.grad, torch.ones_like(x))
