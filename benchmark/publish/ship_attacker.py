"""Ship a lens-independent trained attacker's weights in the package: ``python -m benchmark pretrain-attacker``.

These qualify: ``nafnet-known-psf``'s pre-training across the lens family (``ship_known_psf``),
``learned-reader``'s pre-training on sharp plates (``ship_reader``; every lens's fit
starts from it), ``learned-reader-psf``'s across the lens family on Wiener estimates (``ship_reader_family``)
and ``nafnet-generic`` (its training knows no lens, see ``attacks.restorers.nafnet_generic``). The
command fits it exactly as a run does (the profile's budget, the TRAIN crops of the seed; loaded from
the cache when a run already trained it), then writes ``attacks/weights/nafnet-generic-<profile>-s<seed>
.safetensors`` and its provenance: the cache key the attacker will look it up by, the commit, the
fit seconds (None when it came from the cache), and a check score that
``tests/attacks/training/test_shipped_weights.py`` re-measures: the mean PSNR on ``CHECK_CROPS`` training crops
degraded by a fixed draw of the generic degradations, before and after the network.
"""

from __future__ import annotations

import argparse
import time
from pathlib import Path
from typing import Any

import torch
from safetensors.torch import save as save_safetensors

import lenses
from attacks.training.degradations import degrade
from attacks.restorers.gray_world import gray_world_balance
from attacks.readers.learned_reader import LearnedReader, pack_weights, pretrain, pretrained_key, unpack_weights
from attacks.readers.learned_reader_psf import family_key
from attacks.training.reader_family_training import pretrain_family
from common.plate_render import PLATE_FORMAT
from attacks.restorers.nafnet_generic import NafnetGeneric
from attacks.restorers.nafnet_known_psf import PRETRAIN_SEED, SHIPPED_SCENES, NafnetKnownPSF, pack, shipped_key, unpack
from attacks.training.psf_restorer_training import PSF_BUDGETS
from attacks.training.psf_restorer_training import pretrain as pretrain_known_psf
from attacks.training.restorer_training import collect_pairs, data_identity
from attacks.training.shipped_weights import find_shipped, write_shipped
from benchmark.store.cache import cache_root
from benchmark.results.metrics import psnr
from benchmark.store.profiles import Profile, get_profile
from benchmark.store.provenance import git_commit, package_versions
from benchmark.runner.config import RunConfig
from benchmark.runner.tasks import fit_context
from benchmark.runner.sensing import to_tensor
from benchmark.scenes.loading import load_scenes

__all__ = ["CHECK_CROPS", "CHECK_SEED", "check_scores", "generic_context", "main"]

CHECK_CROPS = 8        # training crops of the recorded check
CHECK_SEED = 20261124  # seed of the check's degradation draw


def generic_context(profile: Profile, seed: int, cache_dir: Path) -> Any:
    """The fit context a run gives ``nafnet-generic`` (the lens only supplies pairs it ignores)."""
    cfg = RunConfig(lenses=["ideal"], attacks=["nafnet-generic"], scenes="synthetic", profile=profile, seeds=[seed],
                    cache_dir=cache_dir)
    lens = lenses.load("ideal", profile=profile, seed=seed, cache_dir=cache_dir, scenes="synthetic")
    return fit_context(lens, cfg, seed, None)


def check_scores(attacker: NafnetGeneric, ctx: Any) -> dict[str, float]:
    """Mean PSNR (dB) of ``CHECK_CROPS`` sharp training crops degraded by a fixed draw, before
    (gray-world balanced, as the network sees them) and after ``attacker.restore``."""
    _, sharp = collect_pairs(ctx.train_pairs, CHECK_CROPS)
    degraded = degrade(sharp, torch.Generator().manual_seed(CHECK_SEED))
    with torch.no_grad():
        restored = attacker.restore(degraded)
    return {"crops": int(sharp.shape[0]), "seed": CHECK_SEED,
            "psnr_in_db": float(psnr(gray_world_balance(degraded).clamp(0, 1), sharp).mean()),
            "psnr_out_db": float(psnr(restored, sharp).mean())}


def ship_reader(args: argparse.Namespace) -> int:
    """Pre-train ``learned-reader`` on sharp plates (seeded; the profile plays no part) and ship it
    with its held-out curve, which ``tests/attacks/readers/test_learned_reader.py`` checks the weights against."""
    net = LearnedReader.build(PLATE_FORMAT, args.seed)
    curve = pretrain(net, PLATE_FORMAT, args.seed)
    made = {"commit": git_commit(), "command": f"python -m benchmark pretrain-attacker learned-reader --seed {args.seed}",
            "seed": args.seed, "fit_s": curve.seconds, "threads": torch.get_num_threads(),
            "packages": package_versions(), "curve": curve.to_dict()}
    path = write_shipped(f"learned-reader-sharp-s{args.seed}", LearnedReader.name, pretrained_key(PLATE_FORMAT, args.seed),
                         pack_weights(net, curve), made, args.out)
    print(f"wrote {path} ({path.stat().st_size / 1e6:.1f} MB) and its provenance; held-out exact-plate accuracy "
          + ", ".join(f"{w} px {a:.2f}" for w, a in curve.per_width[curve.kept].items())
          + f" after {curve.steps[-1]} steps ({curve.stopped}{', still rising' if curve.still_rising else ''})")
    return 0


def ship_reader_family(args: argparse.Namespace, reads: str = "sensor") -> int:
    """Pre-train the learned reader across the lens family from the shipped sharp start and ship it with
    its held-out curve (``attacks.training.reader_family_training``): reading the sensor image
    (``learned-reader --family``), or the Wiener estimate with the lens's PSF (``learned-reader-psf``,
    which reads with it). Resumable: the checkpoint after every evaluation is in the cache
    (``<cache>/pretrain/<name>-s<seed>.pt``)."""
    sharp = find_shipped(LearnedReader.name, pretrained_key(PLATE_FORMAT, args.seed))
    if sharp is None:
        raise SystemExit(f"error: the family pre-training continues the sharp start, and the package ships none for "
                         f"seed {args.seed}; make it first: python -m benchmark pretrain-attacker learned-reader "
                         f"--seed {args.seed}")
    key = family_key(PLATE_FORMAT, args.seed, reads)
    kind, name = key["attack"], f"{key['attack']}-family-s{args.seed}"
    command = (f"python -m benchmark pretrain-attacker {kind}{' --family' if reads == 'sensor' else ''} "
               f"--seed {args.seed}")
    net = LearnedReader.build(PLATE_FORMAT, args.seed)
    unpack_weights(net, sharp.data)
    checkpoint = cache_root() / "pretrain" / f"{name}.pt"
    curve, held_out = pretrain_family(net, PLATE_FORMAT, args.seed, checkpoint=checkpoint, progress=print, reads=reads)
    made = {"commit": git_commit(), "command": command, "reads": reads,
            "seed": args.seed, "fit_s": curve.seconds, "threads": torch.get_num_threads(),
            "packages": package_versions(), "curve": curve.to_dict(), "heldout_lenses": held_out,
            "start": sharp.describe()}
    path = write_shipped(name, kind, key, pack_weights(net, curve), made, args.out)
    print(f"wrote {path} ({path.stat().st_size / 1e6:.1f} MB) and its provenance; held-out exact-plate accuracy "
          f"{curve.accuracy[curve.kept]:.3f} (start {curve.accuracy[0]:.3f}) at step {curve.best_step} of "
          f"{curve.steps[-1]} ({curve.stopped}{', still rising' if curve.still_rising else ''})")
    return 0


def ship_known_psf(args: argparse.Namespace) -> int:
    """Pre-train ``nafnet-known-psf`` across the lens family on the scenes ``SHIPPED_SCENES`` names and ship
    it with its held-out curve. Resumable: the checkpoint after every evaluation is in the cache
    (``<cache>/pretrain/nafnet-known-psf-s0-<steps>.pt``); running the command again continues from it. A
    budget of several cosine cycles continues, at its last restart, from the shipped weights of its first
    cycles where the package has them (``PsfPretrainBudget.first_cycles``), else trains them too."""
    s = SHIPPED_SCENES
    size = (int(s["size"][0]), int(s["size"][1]))
    train = to_tensor(load_scenes(s["scenes"], s["train_split"], s["n_train"], size, s["scene_seed"]))
    heldout = to_tensor(load_scenes(s["scenes"], s["heldout_split"], s["n_heldout"], size, s["scene_seed"]))
    budget = PSF_BUDGETS["full"]
    checkpoint = cache_root() / "pretrain" / f"nafnet-known-psf-s{PRETRAIN_SEED}-{budget.max_steps}.pt"
    previous, warm, start = budget.first_cycles(), None, None
    if previous is not None and not checkpoint.exists():
        found = find_shipped(NafnetKnownPSF.name, shipped_key(previous))
        if found is not None:
            net, before = unpack(found.data, previous)
            if before is not None:
                warm, start = (net.state_dict(), before), found.describe()
                print(f"continuing from {found.path.name} (step {before.steps[-1]}) at a warm restart")
    net, curve = pretrain_known_psf(budget, train, heldout, PRETRAIN_SEED, checkpoint=checkpoint, progress=print,
                                    warm_start=warm)
    made = {"commit": git_commit(), "command": "python -m benchmark pretrain-attacker nafnet-known-psf",
            "seed": PRETRAIN_SEED, "fit_s": round(curve.seconds, 1), "threads": torch.get_num_threads(),
            "packages": package_versions(), "curve": curve.to_dict(),
            "training_data": data_identity(train), "heldout_data": data_identity(heldout),
            **({"warm_start": start} if start is not None else {})}
    name = f"nafnet-known-psf-full-s{PRETRAIN_SEED}" if previous is None else \
        f"nafnet-known-psf-full{budget.max_steps}-s{PRETRAIN_SEED}"
    path = write_shipped(name, NafnetKnownPSF.name, shipped_key(budget), pack(net, curve), made, args.out)
    print(f"wrote {path} ({path.stat().st_size / 1e6:.1f} MB) and its provenance; held-out PSNR "
          f"{max(curve.heldout_psnr_db):.2f} dB (Wiener alone {curve.wiener_psnr_db:.2f} dB) at step "
          f"{curve.kept_step} of {curve.steps[-1]} ({curve.stopped}{', still rising' if curve.still_rising else ''})")
    return 0


def main(args: argparse.Namespace) -> int:
    """`python -m benchmark pretrain-attacker` (arguments from `benchmark.cli`): fit or load, then ship."""
    if getattr(args, "family", False) and args.attacker != "learned-reader":
        raise SystemExit(f"error: --family is a pre-training of learned-reader, not of {args.attacker}")
    if args.attacker == "learned-reader":
        return ship_reader_family(args) if getattr(args, "family", False) else ship_reader(args)
    if args.attacker == "learned-reader-psf":
        return ship_reader_family(args, reads="wiener")
    if args.attacker == "nafnet-known-psf":
        return ship_known_psf(args)
    profile = get_profile(args.profile)
    commit = git_commit()
    ctx = generic_context(profile, args.seed, cache_root())
    attacker = NafnetGeneric(backend="torch", use_shipped=False)
    t0 = time.perf_counter()
    attacker.fit(ctx)
    fit_s = time.perf_counter() - t0
    assert attacker.network is not None and attacker.budget is not None
    model = attacker.network
    state = {k: v.detach().cpu().contiguous() for k, v in model.state_dict().items()}
    key = attacker.cache_key(ctx)
    made = {"commit": commit, "command": f"python -m benchmark pretrain-attacker {args.attacker} --profile "
                                         f"{args.profile} --seed {args.seed}",
            "profile": args.profile, "seed": args.seed, "trained_here": attacker.trained,
            "fit_s": round(fit_s, 1) if attacker.trained else None, "threads": torch.get_num_threads(),
            "packages": package_versions(), "check": check_scores(attacker, ctx)}
    path = write_shipped(f"{args.attacker}-{args.profile}-s{args.seed}", attacker.name, key,
                         save_safetensors(state, metadata={"kind": attacker.name}), made, args.out)
    check = made["check"]
    print(f"wrote {path} ({path.stat().st_size / 1e6:.1f} MB) and its provenance; check PSNR "
          f"{check['psnr_in_db']:.2f} -> {check['psnr_out_db']:.2f} dB on {check['crops']} crops")
    return 0
