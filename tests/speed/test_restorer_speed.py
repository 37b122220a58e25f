"""Restorer inference speed at 512 x 1024: torch against ONNX Runtime (one image), and ONNX Runtime
batched (the engine's pixel budget: 2 images a call, as the evaluation hands them over) against one
image at a time.

Run with `pytest tests/speed/test_restorer_speed.py --benchmark-only`. Both paths of a
comparison alternate in the same rounds, so both see the same load on the shared machine; the
throughputs and their ratio go to `extra_info`. Targets: ``backend="auto"`` as fast as the
faster of torch and ONNX Runtime on the machine (within timing noise), batching no slower than one
image at a time, and the NAFNet folded for inference more than 1.1x the plain one.
The chart test at the end is an ordinary test and runs by default.
"""

from __future__ import annotations

from collections.abc import Callable

import pytest
import torch

from attacks.networks import RED10
from attacks.networks.nafnet_folded import fold_for_inference
from attacks.backends.onnx_runtime import InferenceEngine
from attacks.training.restorer_training import RestorerBudget
from benchmark.results.charts.restorers import restorer_points, write_restorer_speed_chart
from benchmark.results.schema import migrate_legacy_row
from benchmark.store.profiles import PROFILES

from alternating import best_seconds

ROUNDS = 3
BATCH_ROUNDS = 2


def _quick_nafnet() -> torch.nn.Module:
    model = RestorerBudget.from_profile(PROFILES["quick"]).build_nafnet()
    with torch.no_grad():  # non-zero block scales, as after training (zeros skip nothing anyway)
        for name, p in model.named_parameters():
            if name.endswith(("beta", "gamma")):
                p.fill_(0.1)
    return model.eval()


def _quick_red10() -> torch.nn.Module:
    return RED10(width=PROFILES["quick"].adversary_width).eval()


def _race(benchmark, slow: tuple[str, Callable[[], object]], fast: tuple[str, Callable[[], object]], images: int,
          rounds: int) -> float:
    """Best seconds of both runs alternating (`alternating.best_seconds`), the fast one timed for pytest-benchmark;
    each one's images/s and the speedup (`<fast>_speedup`) go to `extra_info`. Returns the speedup."""
    best = best_seconds(dict([slow, fast]), rounds)
    benchmark.pedantic(fast[1], rounds=1, iterations=1, warmup_rounds=0)
    speedup = best[slow[0]] / best[fast[0]]
    benchmark.extra_info.update({f"{slow[0]}_images_per_s": images / best[slow[0]],
                                 f"{fast[0]}_images_per_s": images / best[fast[0]],
                                 f"{fast[0]}_speedup": speedup, "threads": torch.get_num_threads()})
    return speedup


@pytest.mark.parametrize("make", [_quick_nafnet, _quick_red10], ids=["nafnet-quick", "red10-quick"])
def test_restorer_auto_backend_is_the_faster_one(benchmark, make):
    """``backend="auto"`` (what the restorers use) runs at the speed of the faster of torch and ONNX Runtime
    on this machine, within 10 % timing noise. Which one is faster is the machine's: ONNX Runtime ran the
    quick NAFNet 1.8x and RED10 1.7x torch on the 2-core AVX2 machine, RED10 0.98x on a 2-core AVX-512 one
    (2026-11-28), so the target is the choice, not one backend; the ratio goes to ``extra_info``."""
    model = make()
    x = torch.rand(1, 3, 512, 1024)
    engines = {name: InferenceEngine(model, name) for name in ("torch", "onnx", "auto")}
    best = best_seconds({name: (lambda e=engine: e(x)) for name, engine in engines.items()}, ROUNDS)
    benchmark.pedantic(lambda: engines["auto"](x), rounds=1, iterations=1, warmup_rounds=0)
    fastest = min(best["torch"], best["onnx"])
    benchmark.extra_info.update({f"{name}_images_per_s": 1 / seconds for name, seconds in best.items()}
                                | {"onnx_speedup": best["torch"] / best["onnx"], "auto_chose": engines["auto"].backend,
                                   "threads": torch.get_num_threads()})
    assert engines["auto"].backend in ("torch", "onnx")
    assert best["auto"] <= 1.1 * fastest, (
        f"auto ({engines['auto'].backend}) {best['auto']:.3f} s, torch {best['torch']:.3f} s, onnx {best['onnx']:.3f} s")


@pytest.mark.parametrize("make", [_quick_nafnet, _quick_red10], ids=["nafnet-quick", "red10-quick"])
def test_restorer_batched_vs_one_at_a_time(benchmark, make):
    model = make()
    x = torch.rand(4, 3, 512, 1024)
    batched = InferenceEngine(model, "onnx")
    assert [b.shape[0] for b in batched.batches(x)] == [2, 2]
    single = InferenceEngine(model, "onnx", batch_pixels=1)
    speedup = _race(benchmark, ("one_at_a_time", lambda: single(x)), ("batched", lambda: batched(x)), 4,
                    BATCH_ROUNDS)
    # RED10 once measured flat (1.76 vs 1.72 images/s), so "no slower" within 10 % of timing noise. On the 2-core
    # AVX-512 machine (2026-11-29) the plain NAFNet ran 0.90-0.94x in batches of 2 (0.71x in batches of 4, the
    # budget before), RED10 1.13-1.15x: there the target holds for RED10 and only just, if at all, for NAFNet.
    assert speedup > 0.9, f"batches of 2 at 512 x 1024 run {speedup:.2f}x one image at a time"


def test_folded_nafnet_vs_plain_in_onnx_runtime(benchmark):
    """The NAFNet restorers run their network folded (attacks.networks.nafnet_folded): more than 1.1x
    the plain graph's throughput in ONNX Runtime at 512 x 1024, two images a call as in a run
    (measured 1.24x, 2026-11-27)."""
    model = _quick_nafnet()
    x = torch.rand(2, 3, 512, 1024)
    plain = InferenceEngine(model, "onnx")
    folded = InferenceEngine(fold_for_inference(model), "onnx")
    speedup = _race(benchmark, ("plain", lambda: plain(x)), ("folded", lambda: folded(x)), 2, ROUNDS)
    assert speedup > 1.1, f"the folded NAFNet runs {speedup:.2f}x the plain one in ONNX Runtime"


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
