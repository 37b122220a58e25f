"""The ideal-observer reader's candidate blur: the box blur against the whole linear convolution it replaced;
and its boxes searched in two forked workers against one process.

Run with `pytest tests/speed/test_ideal_observer_speed.py --benchmark-only`. Both score the same candidate
plates at boxes of the quick profile's readable widths through the gp lens (PSF 87 x 87), alternating in
the same rounds. The reads agree (tests/lenses/test_raw_likelihood.py checks the blur to 1e-10; on 9 quick
os-d-1000 plate windows both read the same strings, 37.7 s -> 10.6 s on the 2-core machine, 2026-12-05).
"""

from __future__ import annotations

import os

import numpy as np
import pytest
import torch

import attacks
import lenses
from attacks.base import ReadHints
from attacks.readers import ideal_observer_reader as io
from common.plate_render import random_plate_text
from lenses.raw_likelihood import raw_mean_electrons

from alternating import best_seconds

# Measured on the 2-core AMD EPYC (quiet, 2026-12-05): 3.7x here; the whole search on three plates 3.9x.
TARGET_SPEEDUP = 2.5
BOXES = [(10, 20, 58, 30), (91, 41, 155, 55), (170, 60, 250, 77)]  # 48, 64 and 80 px wide


def whole_transform_blur(self: io._Scorer, radiance: torch.Tensor) -> torch.Tensor:
    """The scorer's blur before the box blur: the whole linear convolution, then the box cut out of it."""
    r, (w, h) = self.cam["psf"].shape[-1] // 2, self.size
    phase = (self.origin[0] - r, self.origin[1] - r)
    means = raw_mean_electrons(radiance, 0.0, self.cam["psf"], self.cam["electrons_per_unit"], phase)
    return means[:, r:r + h, r:r + w].reshape(radiance.shape[0], -1)


@pytest.mark.benchmark(group="ideal-observer")
def test_box_blur_scores_candidates_faster(benchmark, monkeypatch):
    reader = attacks.load("ideal-observer")
    reader.fit(attacks.FitContext(lens=lenses.load("gp")))
    rng = np.random.default_rng(0)
    texts = [random_plate_text(rng) for _ in range(64)]
    electrons = 400 + 50 * torch.rand(96, 256, generator=torch.Generator().manual_seed(0), dtype=torch.float64)
    scorers = []
    for x0, y0, x1, y1 in BOXES:
        observed = electrons[y0:y1, x0:x1].reshape(-1)
        scorers.append(io._Scorer(reader._camera, (x1 - x0, y1 - y0), (y0, x0), observed, 1 / observed))
    box_blur = io._Scorer._blurred

    def run(blur):
        def go():
            monkeypatch.setattr(io._Scorer, "_blurred", blur)
            return [s.score(texts, True) for s in scorers]
        return go

    new, old = run(box_blur)(), run(whole_transform_blur)()
    for a, b in zip(new, old):
        torch.testing.assert_close(a, b, rtol=1e-9, atol=1e-6)
    best = best_seconds({"whole": run(whole_transform_blur), "box": run(box_blur)}, 3)
    benchmark.pedantic(run(box_blur), rounds=1, iterations=1, warmup_rounds=0)
    speedup = best["whole"] / best["box"]
    benchmark.extra_info.update({"speedup": speedup, "threads": torch.get_num_threads()})
    assert speedup >= TARGET_SPEEDUP, f"box blur: {speedup:.2f}x the whole transform"


def defocus_reader(workers: int) -> io.IdealObserverReader:
    """A narrow search (beam 3, two sweeps) fitted to defocus, searching in `workers` processes; skips
    where this machine has fewer than 2 CPUs."""
    if len(os.sched_getaffinity(0)) < 2:
        pytest.skip("needs 2 CPUs")
    reader = io.IdealObserverReader(beams=(3,), max_sweeps=2, workers=workers)
    reader.fit(attacks.FitContext(lens=lenses.load("defocus")))
    return reader


def speedup_of(benchmark, runs: dict, slow: str, fast: str) -> float:
    """How many times faster run `fast` is than run `slow` (alternating rounds), once both read the same."""
    assert runs[slow]() == runs[fast]()
    best = best_seconds(runs, 2)
    benchmark.pedantic(runs[fast], rounds=1, iterations=1, warmup_rounds=0)
    speedup = best[slow] / best[fast]
    benchmark.extra_info.update({"speedup": speedup})
    return speedup


# Measured on the 2-core AMD EPYC (quiet, 2026-12-05): 4 plates of two images through defocus, 10.5-11.6 s in
# one process, 7.1-7.3 s in two workers (1.5x; the boxes differ in cost, so the two workers do not finish together).
TARGET_WORKERS_SPEEDUP = 1.3


@pytest.mark.benchmark(group="ideal-observer")
def test_two_workers_search_the_boxes_faster_than_one(benchmark):
    readers = {workers: defocus_reader(workers) for workers in (1, 2)}
    images = torch.rand(2, 3, 96, 256, generator=torch.Generator().manual_seed(0)) * 0.2 + 0.3  # noise, no plate
    hints = ReadHints(plate_boxes=[BOXES[:2], BOXES[1:]])
    runs = {f"{w} worker(s)": (lambda r=r: r.read(images, hints)) for w, r in readers.items()}
    speedup = speedup_of(benchmark, runs, "1 worker(s)", "2 worker(s)")
    assert speedup >= TARGET_WORKERS_SPEEDUP, f"two workers: {speedup:.2f}x one process"


# Measured on the 2-core AMD EPYC (quiet, 2026-12-06): in a run, the cascade's windows come in batches of one
# size, many of one window. Read batch by batch, a batch of one window searches in one process; in one
# read_batches call every box shares the pool (four one-window batches here: 1.87x). In a fresh quick
# run --lens gp the cascade went from about 130 s to 76 s on 61 plates.
TARGET_POOLED_SPEEDUP = 1.3


@pytest.mark.benchmark(group="ideal-observer")
def test_one_pool_over_every_batch_beats_a_pool_per_batch(benchmark):
    reader = defocus_reader(2)
    generator = torch.Generator().manual_seed(1)
    batches = [(torch.rand(1, 3, 96, 256, generator=generator) * 0.2 + 0.3, ReadHints(plate_boxes=[[box]]))
               for box in BOXES + BOXES[:1]]  # four windows, each a batch of its own
    runs = {"per batch": lambda: [reader.read(images, hints) for images, hints in batches],
            "pooled": lambda: reader.read_batches(batches)}
    speedup = speedup_of(benchmark, runs, "per batch", "pooled")
    assert speedup >= TARGET_POOLED_SPEEDUP, f"one pool: {speedup:.2f}x a pool per batch"
