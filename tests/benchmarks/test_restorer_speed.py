"""Restorer inference speed, torch against ONNX Runtime, at 512 x 1024 (one image).

Run with `pytest tests/benchmarks/test_restorer_speed.py --benchmark-only`. Each benchmark
times the ONNX Runtime path with pytest-benchmark and the torch path by hand in the same run
(same rounds), and stores both throughputs and their ratio in `extra_info`.
The chart test at the end is an ordinary test and runs by default.
"""

from __future__ import annotations

import time

import pytest
import torch

from attacks.networks import RED10
from attacks.onnx_backend import InferenceEngine
from attacks.restorer_training import RestorerBudget
from benchmark.charts.restorers import restorer_points, write_restorer_speed_chart
from benchmark.schema import migrate_legacy_row
from benchmark.profiles import PROFILES

ROUNDS = 3


def _quick_nafnet() -> torch.nn.Module:
    model = RestorerBudget.from_profile(PROFILES["quick"]).build_nafnet()
    with torch.no_grad():  # non-zero block scales, as after training (zeros skip nothing anyway)
        for name, p in model.named_parameters():
            if name.endswith(("beta", "gamma")):
                p.fill_(0.1)
    return model.eval()


def _quick_red10() -> torch.nn.Module:
    return RED10(width=PROFILES["quick"].adversary_width).eval()


@pytest.mark.parametrize("make", [_quick_nafnet, _quick_red10], ids=["nafnet-quick", "red10-quick"])
def test_restorer_throughput_torch_vs_onnx(benchmark, make):
    model = make()
    x = torch.rand(1, 3, 512, 1024)
    torch_engine = InferenceEngine(model, "torch")
    onnx_engine = InferenceEngine(model, "onnx")
    torch_engine(x)
    torch_s = []
    for _ in range(ROUNDS):
        t0 = time.perf_counter()
        torch_engine(x)
        torch_s.append(time.perf_counter() - t0)
    benchmark.pedantic(lambda: onnx_engine(x), rounds=ROUNDS, iterations=1, warmup_rounds=1)
    torch_ips = 1.0 / min(torch_s)
    onnx_ips = 1.0 / benchmark.stats.stats.min
    benchmark.extra_info.update({"torch_images_per_s": torch_ips, "onnx_images_per_s": onnx_ips,
                                 "onnx_speedup": onnx_ips / torch_ips, "threads": torch.get_num_threads()})


def test_restorer_chart_has_one_point_per_lens_and_restorer(tmp_path):
    rows = [migrate_legacy_row({"profile": "smoke", "scenes": "synthetic", **row}) for row in [
        {"lens": "defocus", "attack": "wiener-known-psf", "psnr_db": 24.5, "images_per_s": 1.6,
         "threat_model": "lens-access", "seed": 0},
        {"lens": "defocus", "attack": "wiener-known-psf", "psnr_db": 25.5, "images_per_s": 2.4,
         "threat_model": "lens-access", "seed": 1},
        {"lens": "ideal", "attack": "nafnet-known-pairs", "psnr_db": 27.0, "images_per_s": 0.5,
         "threat_model": "known-pairs", "seed": 0},
        {"lens": "ideal", "attack": "nafnet-known-pairs>lpdr", "plate_acc": 0.3, "images_per_s": 3.0, "seed": 0},
        {"lens": "sharp", "attack": "lpdr", "plate_acc": 0.4, "images_per_s": 3.0, "seed": 0},
        {"lens": "ideal", "attack": "lens", "images_per_s": 10.0, "seed": 0},
    ]]
    points = restorer_points(rows)
    assert points == {("defocus", "wiener-known-psf"): (2.0, 25.0, "lens-access"),
                      ("ideal", "nafnet-known-pairs"): (0.5, 27.0, "known-pairs")}
    path = write_restorer_speed_chart(rows, tmp_path / "charts" / "restorers.png")
    assert path.is_file() and path.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
