"""Ship a co-designed lens in the package: ``python -m benchmark ship-lens NAME``.

The command co-designs the lens exactly as a run does (or loads the run from the cache), copies the
finished run folder into ``benchmark/codesign/shipped/`` (``benchmark.codesign.shipped``), and fits
the lens's known-pairs NAFNet and fine-tunes its learned reader, whose weights go to ``attacks/weights/``
under the key a run looks them up by (``attacks.training.shipped_weights``). A fresh ``python -m benchmark run
--lens NAME`` at that profile and seed then neither co-designs nor fits those attackers; every number it
prints is the same.

Each provenance records the commit, the command, the machine, the training seconds and a check that
``tests/benchmark/codesign/test_shipped_lens.py`` re-measures: the mIoU of the lens's own utility net
on ``CHECK_SCENES`` val scenes seen through the lens, and the known-pairs NAFNet's PSNR on
``CHECK_CROPS`` crops of its training pairs before and after.
"""

from __future__ import annotations

import argparse
import platform
import time
from pathlib import Path
from typing import Any

import torch
from safetensors.torch import save as save_safetensors

from attacks.readers.learned_reader import LearnedReader, pack_weights
from attacks.restorers.nafnet_known_pairs import NafnetKnownPairs
from attacks.training.restorer_training import collect_pairs, random_crops
from attacks.training.shipped_weights import write_shipped
from benchmark.store.cache import cache_root
from benchmark.codesign.codesigned_lenses import START_SPEC, attach
from benchmark.codesign.schemes import SCHEMES
from benchmark.codesign.shipped import ship_run
from benchmark.codesign.trainer import CoDesign
from benchmark.results.metrics import psnr
from benchmark.store.profiles import Profile, get_profile
from benchmark.store.provenance import git_commit, package_versions
from benchmark.runner.config import RunConfig
from benchmark.scenes.loading import load_scenes
from benchmark.runner.sensing import sense, to_tensor
from benchmark.runner.tasks import fit_context
from benchmark.runner.utility_measure import utility_metrics
import lenses
from lenses.lens import Lens
from lenses.spec import load_spec

__all__ = ["CHECK_CROPS", "CHECK_SCENES", "codesign_run", "known_pairs_check", "lens_check", "main"]

CHECK_SCENES = 4   # val scenes of the recorded utility check
CHECK_CROPS = 8    # training-pair crops of the recorded known-pairs check
CHECK_SEED = 20261128  # seed of the check's crop positions


def codesign_run(name: str, profile: Profile, seed: int, use_shipped: bool = True) -> CoDesign:
    """The co-design run a ``run --lens NAME`` of this profile and seed loads (synthetic scenes, CPU)."""
    return CoDesign(load_spec(START_SPEC), SCHEMES[name], profile, seed, "cpu", cache_root(), use_shipped=use_shipped)


def run_config(name: str, profile: Profile, seed: int) -> RunConfig:
    return RunConfig(lenses=[name], attacks=["nafnet-known-pairs"], scenes="synthetic", profile=profile,
                     seeds=[seed], cache_dir=cache_root())


def lens_check(lens: Lens, name: str, profile: Profile, seed: int) -> dict[str, Any]:
    """mIoU of the lens's own utility net (``lens.utility_net``) on the first ``CHECK_SCENES`` val
    scenes of ``seed``, seen through the lens (noise seeded with ``seed``, as a run senses them)."""
    scenes = load_scenes("synthetic", "val", CHECK_SCENES, profile.image_size, seed)
    sensor = sense(lens, to_tensor(scenes), profile.batch_size, seed, "cpu")
    metrics = utility_metrics(lens.utility_net, sensor, scenes, run_config(name, profile, seed), lens)
    return {"scenes": CHECK_SCENES, "seed": seed, "miou": metrics["miou"]}


def known_pairs_check(attacker: NafnetKnownPairs, ctx: Any) -> dict[str, Any]:
    """Mean PSNR (dB) of ``CHECK_CROPS`` crops of the attacker's training pairs: the sensor crop
    (as it comes) and the attacker's restoration, each against the sharp crop."""
    assert attacker.budget is not None
    sensor, sharp = collect_pairs(ctx.train_pairs, attacker.budget.max_train_images)
    inp, target = random_crops([sensor, sharp], CHECK_CROPS, attacker.budget.crop_px,
                               torch.Generator().manual_seed(CHECK_SEED))
    with torch.no_grad():
        restored = attacker.restore(inp)
    return {"crops": CHECK_CROPS, "seed": CHECK_SEED, "psnr_in_db": float(psnr(inp.clamp(0, 1), target).mean()),
            "psnr_out_db": float(psnr(restored, target).mean())}


def _machine() -> str:
    return f"{platform.machine()}, {torch.get_num_threads()} torch threads, {platform.processor() or 'cpu'}"


def main(args: argparse.Namespace) -> int:
    """`python -m benchmark ship-lens` (arguments from `benchmark.cli`): co-design or load, fit, ship."""
    profile = get_profile(args.profile)
    made: dict[str, Any] = {"commit": git_commit(), "profile": args.profile, "seed": args.seed,
                            "command": f"python -m benchmark ship-lens {args.lens} --profile {args.profile} "
                                       f"--seed {args.seed}",
                            "machine": _machine(), "packages": package_versions()}
    if args.reader_only:
        made["command"] += " --reader-only"
        lens = lenses.load(args.lens, profile=profile, seed=args.seed, device="cpu", cache_dir=cache_root())
        ctx = fit_context(lens, run_config(args.lens, profile, args.seed), args.seed, None)
        ship_learned_reader(ctx, args, made)
        return 0
    run = codesign_run(args.lens, profile, args.seed, use_shipped=False)
    cached = run.load()
    trained = cached or run.train()
    lens = attach(trained)
    record = trained.record
    folder = ship_run(trained.directory, run.config,
                      {**made, "trained_here": cached is None, "train_s": round(float(record["train_s"]), 1),
                       "seconds_per_step": record.get("seconds_per_step"),
                       "check": lens_check(lens, args.lens, profile, args.seed)}, args.out)
    print(f"wrote {folder} ({sum(p.stat().st_size for p in folder.iterdir()) / 1e6:.1f} MB) and its provenance")

    ctx = fit_context(lens, run_config(args.lens, profile, args.seed), args.seed, None)
    attacker = NafnetKnownPairs(backend="torch", use_shipped=False)
    t0 = time.perf_counter()
    attacker.fit(ctx)
    assert attacker.network is not None
    state = {k: v.detach().cpu().contiguous() for k, v in attacker.network.state_dict().items()}
    check = known_pairs_check(attacker, ctx)
    weights = write_shipped(
        f"{attacker.name}-{args.lens}-{args.profile}-s{args.seed}", attacker.name, attacker.cache_key(ctx),
        save_safetensors(state, metadata={"kind": attacker.name}),
        {**made, "trained_here": attacker.trained,
         "fit_s": round(time.perf_counter() - t0, 1) if attacker.trained else None, "check": check},
        None if args.out is None else args.out / "attack_weights")
    print(f"wrote {weights} ({weights.stat().st_size / 1e6:.1f} MB) and its provenance; check PSNR "
          f"{check['psnr_in_db']:.2f} -> {check['psnr_out_db']:.2f} dB on {check['crops']} crops")
    ship_learned_reader(ctx, args, made)
    return 0


def ship_learned_reader(ctx: Any, args: argparse.Namespace, made: dict[str, Any]) -> Path:
    """Fine-tune (or load from the cache) learned-reader on the lens as a run does and ship the fit under
    the key a run looks it up by; the check is its last held-out accuracy per plate width."""
    reader = LearnedReader(use_shipped_fit=False)
    t0 = time.perf_counter()
    reader.fit(ctx)
    assert reader.net is not None and reader.fit_key is not None and reader.curve is not None
    curve = reader.curve
    check = {"steps": curve.steps[-1] if curve.steps else 0, "kept_step": curve.best_step,
             "still_rising": curve.still_rising,
             "held_out_per_width": {str(k): v for k, v in (curve.per_width[curve.kept] if curve.per_width else {}).items()}}
    fit_s = round(time.perf_counter() - t0, 1) if reader.trained else None
    weights = write_shipped(
        f"{reader.name}-{args.lens}-{args.profile}-s{args.seed}", reader.name, reader.fit_key,
        pack_weights(reader.net, curve), {**made, "trained_here": reader.trained, "fit_s": fit_s, "check": check},
        None if args.out is None else args.out / "attack_weights")
    print(f"wrote {weights} ({weights.stat().st_size / 1e6:.1f} MB) and its provenance")
    return weights
