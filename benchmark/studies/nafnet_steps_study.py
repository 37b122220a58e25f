"""Known-pairs NAFNet: held-out PSNR against fit steps and fit seconds, from checkpoints of one long fit.

One ``nafnet-known-pairs`` fit (the attacker's recipe, data and network, ``attacks.training.restorer_training``)
of ``steps`` optimiser steps on one lens and seed is scored at checkpoints on the profile's
held-out val scenes through that lens (mean PSNR of the clamped restoration against the sharp
scene, as the runner scores a restorer). Fit seconds count the training steps only, not the
scoring. A checkpoint at step s of a fit whose cosine schedule spans ``steps`` has not annealed
its learning rate as a fit of s steps would, so the curve is a lower bound on what a fit of s
steps reaches (and the gain at the very end of the long fit partly comes from the annealing).

Run: ``python -m benchmark.studies.nafnet_steps_study`` (writes leaderboard/studies/nafnet_known_pairs_steps.json
and leaderboard/charts/nafnet_known_pairs_steps.png).
"""

from __future__ import annotations

import argparse
import dataclasses
import json
import logging
import os
import time
from collections.abc import Callable
from pathlib import Path
from typing import Any

import numpy as np
import torch

import lenses
from attacks.training.restorer_training import RestorerBudget, collect_pairs, random_crops, train_restorer
from benchmark.store.cache import atomic_write_text, cache_root
from benchmark.results.metrics import psnr
from benchmark.store.profiles import Profile, get_profile
from benchmark.store.provenance import provenance
from benchmark.runner.config import RunConfig
from benchmark.scenes import load_scenes
from benchmark.runner.sensing import batches, sense, to_tensor, train_pairs_factory

CHECKPOINTS = (25, 50, 100, 150, 200, 300, 400, 500, 600, 700, 800)
TAIL_FRACTION = 0.2
"""Rule: a step budget s is enough when its last ``TAIL_FRACTION`` of steps adds < ``MIN_GAIN_DB``."""
MIN_GAIN_DB = 0.2


def measure(profile: Profile, lens_name: str = "defocus", seed: int = 0,
            checkpoints: tuple[int, ...] = CHECKPOINTS, cache_dir: Path | None = None, eval_hw: tuple[int, int] | None = None,
            on_record: Callable[[list[dict[str, float]]], None] | None = None) -> list[dict[str, float]]:
    """One record per checkpoint: ``step``, ``fit_s`` (training seconds so far; ``pairs_s``, the seconds
    spent sensing the training pairs once before, is apart), ``psnr_db`` (mean held-out
    PSNR over the profile's ``n_val`` val scenes, dB) and ``train_psnr_db`` (mean training-batch PSNR of
    the last 10 steps, dB).

    The fit runs ``max(checkpoints)`` steps with the profile's NAFNet size, crops and batch. ``eval_hw``
    (h, w) scores the centre crop of that size of every sensed val image (None: whole images), to
    keep scoring cheap next to training. ``on_record`` sees the records after every checkpoint.
    """
    if not checkpoints or min(checkpoints) < 1:
        raise ValueError(f"checkpoints must be positive step counts, got {checkpoints}")
    cache_dir = Path(cache_dir or cache_root())
    steps = max(checkpoints)
    cfg = RunConfig(lenses=[lens_name], attacks=[], scenes="synthetic", profile=profile, seeds=[seed],
                    cache_dir=cache_dir)
    lens = lenses.load(lens_name, profile=profile, seed=seed, cache_dir=cache_dir, scenes="synthetic")
    sharp = to_tensor(load_scenes("synthetic", "val", profile.n_val, profile.image_size, seed))
    sensor = sense(lens, sharp, profile.batch_size, seed, "cpu")
    if eval_hw is not None:
        top, left = (sharp.shape[2] - eval_hw[0]) // 2, (sharp.shape[3] - eval_hw[1]) // 2
        sharp = sharp[:, :, top:top + eval_hw[0], left:left + eval_hw[1]]
        sensor = sensor[:, :, top:top + eval_hw[0], left:left + eval_hw[1]]
    budget = RestorerBudget.from_budget(dataclasses.replace(profile, restorer_steps=steps).attack_budget())
    t0 = time.perf_counter()
    train_sensor, train_sharp = collect_pairs(train_pairs_factory(lens, cfg, seed), budget.max_train_images)
    pairs_s = time.perf_counter() - t0

    def next_batch(generator: torch.Generator) -> tuple[torch.Tensor, torch.Tensor]:
        inp, target = random_crops([train_sensor, train_sharp], budget.batch_size, budget.crop_px, generator)
        return inp, target

    with torch.random.fork_rng(devices=[]):
        torch.manual_seed(seed)
        model = budget.build_nafnet()
    records: list[dict[str, float]] = []
    clock = {"fit_s": 0.0, "since": time.perf_counter()}

    def checkpoint(step: int, net: torch.nn.Module) -> None:
        if step not in checkpoints:
            return
        clock["fit_s"] += time.perf_counter() - clock["since"]
        net.eval()
        with torch.no_grad():
            restored = torch.cat([net(b).clamp(0, 1) for b in batches(sensor, 2)])
        records.append({"step": step, "fit_s": clock["fit_s"], "pairs_s": pairs_s,
                        "psnr_db": float(psnr(restored, sharp).mean())})
        if on_record is not None:
            on_record(records)
        clock["since"] = time.perf_counter()

    losses = train_restorer(model, next_batch, steps, "cpu", seed, checkpoint=checkpoint)
    for r in records:
        r["train_psnr_db"] = float(-np.mean(losses[max(0, int(r["step"]) - 10):int(r["step"])]))
    return records


def flattening_step(records: list[dict[str, float]], tail: float = TAIL_FRACTION,
                    min_gain_db: float = MIN_GAIN_DB) -> int:
    """The smallest checkpointed step s from which on the curve is flat: for s and for every later
    checkpoint t, PSNR(t) - PSNR((1 - tail) t) < ``min_gain_db`` (PSNR between checkpoints linear in
    steps; before the first checkpoint it is not defined, so t must satisfy (1 - tail) t >= the first
    checkpoint). The last checkpoint when the curve never flattens. Requiring every later checkpoint to
    pass too is what rejects a short budget on a curve still rising steadily: the last 20 % of a short
    fit is only a few steps."""
    steps = np.array([r["step"] for r in records], dtype=float)
    values = np.array([r["psnr_db"] for r in records], dtype=float)
    order = np.argsort(steps)
    steps, values = steps[order], values[order]

    def gain(t: float) -> float | None:
        start = (1 - tail) * t
        return None if start < steps[0] else float(np.interp(t, steps, values) - np.interp(start, steps, values))

    gains = [gain(t) for t in steps]
    for i, t in enumerate(steps):
        later = [g for g in gains[i:] if g is not None]
        if gains[i] is not None and all(g < min_gain_db for g in later):
            return int(t)
    return int(steps[-1])


def run(json_path: Path, chart_path: Path | None, profile: Profile, lens_name: str = "defocus", seed: int = 0,
        checkpoints: tuple[int, ...] = CHECKPOINTS, eval_hw: tuple[int, int] | None = None) -> dict[str, Any]:
    """Measure, choose the default by ``flattening_step``, write the study JSON (and the chart).

    The JSON is rewritten after every checkpoint (``complete`` false until the fit ends), so a fit
    stopped early still leaves its checkpoints."""
    t0 = time.perf_counter()

    def write(records: list[dict[str, float]], complete: bool = False) -> dict[str, Any]:
        body = _body(records, profile, lens_name, seed, eval_hw, time.perf_counter() - t0)
        body["complete"] = complete
        atomic_write_text(json_path, json.dumps(body, indent=1, sort_keys=True) + "\n")
        return body

    body = write(measure(profile, lens_name, seed, checkpoints, eval_hw=eval_hw, on_record=write), complete=True)
    if chart_path is not None:
        from benchmark.results.charts.nafnet_steps_chart import write_nafnet_steps_chart
        write_nafnet_steps_chart(body, chart_path)
    return body


def _body(records: list[dict[str, float]], profile: Profile, lens_name: str, seed: int,
          eval_hw: tuple[int, int] | None, wall_s: float) -> dict[str, Any]:
    return {"study": "nafnet_known_pairs_steps", "attack": "nafnet-known-pairs", "lens": lens_name, "seed": seed,
            "profile": profile.to_dict(), "threads": torch.get_num_threads(), "records": records,
            "eval": {"images": profile.n_val, "split": "val", "crop_hw": list(eval_hw) if eval_hw else None},
            "rule": {"tail_fraction": TAIL_FRACTION, "min_gain_db": MIN_GAIN_DB,
                     "text": f"smallest s from which on the last {TAIL_FRACTION:.0%} of steps add < {MIN_GAIN_DB} dB"},
            "chosen_steps": flattening_step(records), "profile_steps": profile.restorer_steps,
            "wall_s": wall_s, "load_average": list(os.getloadavg()), "provenance": provenance("cpu")}


def main(argv: list[str] | None = None) -> int:
    from benchmark.results.entries import LEADERBOARD
    parser = argparse.ArgumentParser(prog="python -m benchmark.studies.nafnet_steps_study", description=__doc__)
    parser.add_argument("--profile", default="quick", help="profile whose NAFNet size and data are used")
    parser.add_argument("--lens", default="defocus")
    parser.add_argument("--seed", type=int, default=0)
    parser.add_argument("--checkpoints", default=",".join(map(str, CHECKPOINTS)),
                        help="comma-separated steps to score at; the fit runs to the largest")
    parser.add_argument("--eval-crop", default="256x512", help="HxW centre crop of the val images scored, or 'full'")
    parser.add_argument("--dir", type=Path, default=LEADERBOARD, help="leaderboard folder")
    args = parser.parse_args(argv)
    logging.basicConfig(level=logging.INFO, format="%(asctime)s %(name)s: %(message)s")
    checkpoints = tuple(sorted({int(s) for s in args.checkpoints.split(",")}))
    body = run(args.dir / "studies" / "nafnet_known_pairs_steps.json",
               args.dir / "charts" / "nafnet_known_pairs_steps.png", get_profile(args.profile), args.lens, args.seed,
               checkpoints, None if args.eval_crop == "full" else _hw(args.eval_crop))
    for r in body["records"]:
        print(f"step {r['step']:5d}  fit {r['fit_s']:7.1f} s  held-out PSNR {r['psnr_db']:.3f} dB")
    print(f"chosen: {body['chosen_steps']} steps (profile default {body['profile_steps']}); "
          f"wall {body['wall_s']:.0f} s")
    return 0


def _hw(text: str) -> tuple[int, int]:
    try:
        h, w = (int(v) for v in text.lower().split("x"))
    except ValueError:
        raise SystemExit(f"--eval-crop must be HxW like 256x512 or 'full', got {text!r}") from None
    return h, w


if __name__ == "__main__":
    raise SystemExit(main())
