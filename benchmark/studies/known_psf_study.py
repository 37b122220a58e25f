"""The family-trained restorers against the published ones, paired per scene: ``python -m benchmark.studies.known_psf_study``.

For each lens (default: ideal, defocus, gp, os, os-d-1000) it rebuilds the lens of the published quick
entry at seed 0 (its ``lens_spec``), senses the entry's own val scenes exactly as the run did
(``benchmark.runner.sensing.sense`` with the run's seed), and restores them with ``wiener-known-psf``
(recomputed: its per-scene PSNR must equal the entry's, which proves the pairing), ``nafnet-known-psf``
(zero-shot, the shipped family pre-training) and, with ``--tuned``, its two fine-tunes on the lens's TRAIN
pairs, ``nafnet-known-pairs-tuned`` (fed the PSF it measures from the pairs) and ``nafnet-known-psf-tuned``
(fed the lens's own PSF). Each is compared per scene with every restorer of the entry and with the
entry's best-per-scene ensemble PSNR (paired bootstrap, ``benchmark.results.stats``), and timed.
Where the lens's full cross product at seed 0 is kept (``leaderboard/studies/cross_product``: the same
val scenes and sensor noise, restored by the attackers of the day it ran), each is also paired per scene
with that run's restorers (``versus_cross_product``): the weights shipped now against those it ran with.
Writes ``leaderboard/studies/known_psf_restorers.json``.
"""

from __future__ import annotations

import argparse
import json
import os
import sys
import time
from pathlib import Path
from typing import Any

import numpy as np
import torch

import attacks
from attacks.base import FitContext
from benchmark.results import stats
from benchmark.results.metrics import psnr
from benchmark.results.schema import read_results
from benchmark.runner.sensing import sense, to_tensor, train_pairs_factory
from benchmark.runner.config import RunConfig
from benchmark.scenes.loading import load_scenes
from benchmark.store.profiles import get_profile
from benchmark.store.provenance import git_commit, package_versions
from lenses.lens import Lens
from lenses.spec import parse_spec

__all__ = ["main", "measure_lens"]

ROOT = Path(__file__).resolve().parents[2]
ENTRIES = ROOT / "leaderboard" / "entries"
CROSS_PRODUCT = ROOT / "leaderboard" / "studies" / "cross_product"
OUT = ROOT / "leaderboard" / "studies" / "known_psf_restorers.json"
LENSES = ("ideal", "defocus", "gp", "os", "os-d-1000")
TUNED = ("nafnet-known-pairs-tuned", "nafnet-known-psf-tuned")


def _entry_units(entry: dict[str, Any], seed: int) -> dict[str, list[float]]:
    """Per-scene PSNR of every restorer row of the entry at ``seed`` (scene order of the units)."""
    return {r["attack"]: r["units"]["values"]["psnr_db"] for r in entry["rows"]
            if r["kind"] == "restorer" and r["seed"] == seed and r["status"] == "ok" and r.get("units")
            and "psnr_db" in r["units"]["values"]}


def _cross_product_units(name: str, seed: int) -> dict[str, list[float]]:
    """Per-scene PSNR of every restorer row of the lens's kept cross-product run at ``seed`` ({} if none)."""
    path = CROSS_PRODUCT / f"{name}.json.gz"
    if not path.is_file():
        return {}
    return {r.attack: [float(v) for v in r.units.values["psnr_db"]] for r in read_results(path).rows
            if r.kind == "restorer" and r.lens == name and r.seed == seed and r.ok and r.units is not None
            and "psnr_db" in r.units.values}


def _compare(a: list[float], b: list[float]) -> dict[str, Any]:
    c = stats.paired_bootstrap(a, b)
    return {"difference_db": round(c.difference, 3), "low_db": round(c.low, 3), "high_db": round(c.high, 3),
            "p_value": c.p_value, "verdict": stats.verdict(c, "greater").label, "n": c.n}


def pair_with_zero_shot(restorers: dict[str, dict[str, Any]]) -> None:
    """Add to each fine-tuned restorer's record (where measured) its per-scene comparison with the zero-shot
    ``nafnet-known-psf`` it started from, in place."""
    zero = restorers.get("nafnet-known-psf")
    for name in TUNED:
        tuned = restorers.get(name)
        if tuned is not None and zero is not None:
            tuned["versus_zero_shot"] = _compare(tuned["per_scene_psnr_db"], zero["per_scene_psnr_db"])


def measure_lens(name: str, tuned: bool, seed: int = 0) -> dict[str, Any]:
    """The study's record for one lens (module docs)."""
    entry = json.loads((ENTRIES / f"{name}__quick__synthetic.json").read_text())
    profile = get_profile("quick")
    lens = Lens(parse_spec(entry["lens_spec"], f"{name} entry"))
    scenes = load_scenes("synthetic", "val", profile.n_val, profile.image_size, seed)
    sharp = to_tensor(scenes)
    sensor = sense(lens, sharp, profile.batch_size, seed, "cpu")
    published = _entry_units(entry, seed)
    crossed = _cross_product_units(name, seed)
    cfg = RunConfig(lenses=[name], attacks=[], scenes="synthetic", profile=profile, seeds=[seed])
    ctx = FitContext(lens=lens, train_pairs=train_pairs_factory(lens, cfg, seed), seed=seed,
                     budget=profile.attack_budget())
    ours: dict[str, dict[str, Any]] = {}
    names = ["wiener-known-psf", "nafnet-known-psf"] + (list(TUNED) if tuned else [])
    for attacker_name in names:
        attacker = attacks.load(attacker_name)
        t0 = time.perf_counter()
        report = attacker.fit(ctx)
        fit_s = time.perf_counter() - t0
        t0 = time.perf_counter()
        with torch.no_grad():
            restored = torch.cat([attacker.restore(sensor[i:i + 8]) for i in range(0, sensor.shape[0], 8)])
        restore_s = time.perf_counter() - t0
        values = [float(v) for v in psnr(restored, sharp)]
        record: dict[str, Any] = {"psnr_db": float(np.mean(values)),
                                  "interval_db": list(stats.bootstrap_mean_interval(values)),
                                  "fit_s": round(fit_s, 1), "restore_s_per_image": round(restore_s / len(values), 3),
                                  "per_scene_psnr_db": [round(v, 4) for v in values],
                                  "versus_published": {k: _compare(values, v) for k, v in published.items()
                                                       if len(v) == len(values)}}
        if crossed:
            record["versus_cross_product"] = {k: _compare(values, v) for k, v in crossed.items()
                                              if len(v) == len(values)}
        if report.curve is not None:
            record["fit_curve"] = {"steps": list(report.curve.steps), "scores": list(report.curve.scores),
                                   "stopped": report.curve.stopped, "kept_step": report.curve.kept_step,
                                   "still_rising": report.still_rising}
        ours[attacker_name] = record
        print(f"{name}: {attacker_name} {record['psnr_db']:.2f} dB (fit {fit_s:.0f} s, {restore_s / len(values):.2f} s/image)")
    if published:
        best = np.max(np.array(list(published.values())), axis=0).tolist()
        for record in ours.values():
            record["versus_published_ensemble"] = _compare(record["per_scene_psnr_db"], best)
    pair_with_zero_shot(ours)
    recomputed = ours["wiener-known-psf"]["per_scene_psnr_db"]
    pairing = (float(np.max(np.abs(np.array(recomputed) - np.array(published["wiener-known-psf"]))))
               if "wiener-known-psf" in published else None)
    return {"lens": name, "seed": seed, "n_scenes": len(scenes), "published_mean_psnr_db":
            {k: float(np.mean(v)) for k, v in published.items()},
            "published_ensemble_psnr_db": float(np.mean(best)) if published else None,
            "wiener_pairing_max_abs_db": pairing,
            "cross_product_wiener_pairing_max_abs_db": (
                float(np.max(np.abs(np.array(recomputed) - np.array(crossed["wiener-known-psf"]))))
                if "wiener-known-psf" in crossed else None),
            "restorers": ours}


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--lens", action="append", default=None, help=f"lens (repeatable; default {', '.join(LENSES)})")
    parser.add_argument("--tuned", action="store_true", help=f"also fine-tune {' and '.join(TUNED)} per lens")
    parser.add_argument("--out", type=Path, default=OUT)
    parser.add_argument("--pair-only", action="store_true",
                        help="measure nothing: add the per-scene pairings to the records already in --out")
    args = parser.parse_args(argv)
    previous = json.loads(args.out.read_text()) if args.out.exists() else {"lenses": {}}
    if args.pair_only:
        for record in previous["lenses"].values():
            pair_with_zero_shot(record["restorers"])
        args.out.write_text(json.dumps(previous, indent=1) + "\n")
        return 0
    for name in args.lens or LENSES:
        previous["lenses"][name] = measure_lens(name, args.tuned)
        previous.update({"commit": git_commit(), "packages": package_versions(), "threads": torch.get_num_threads(),
                         "load_average_1min": os.getloadavg()[0],
                         "command": "python -m benchmark.studies.known_psf_study " + " ".join(
                             sys.argv[1:] if argv is None else argv)})
        args.out.parent.mkdir(parents=True, exist_ok=True)
        args.out.write_text(json.dumps(previous, indent=1) + "\n")  # after each lens: an interrupted study keeps what it measured
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
