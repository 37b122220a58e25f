"""The clean utility net trained to its plateau: SegFormer on sharp scenes, with a learning curve.

Recipe (every number from the profile's ``pretrain_*`` fields): ``pretrain_scenes`` distinct
training scenes, ``pretrain_crop`` crops (half of them centred on a pixel of a uniformly drawn
class, see :mod:`benchmark.codesign.utility.pretrain_data`), AdamW (weight decay 0.01) with a linear
warmup over ``pretrain_warmup`` steps to ``pretrain_lr`` and a cosine decay to 1 % of it at
``pretrain_steps``. Every ``pretrain_eval_every`` steps the net is scored on the profile's sharp
val scenes (``n_val`` scenes of the val split, seed ``seed``, at ``image_size``, by the runner's
sliding window) and the point is appended to the learning curve. The plateau criterion: the last
fifth of training (from the last curve point at or before 80 % of the steps to the end) improves
sharp val mIoU by less than ``PLATEAU_GAIN``.

The run checkpoints at every curve point and resumes from it (batches are a pure function of
(seed, step)); the finished net and its record are cached by a hash of the recipe. Each of these
files carries the cache's checksum (:mod:`benchmark.store.cache`): a corrupt or truncated one is reported
with its path and removed, a corrupt checkpoint restarts training from step 0, a corrupt net or
record trains the net again.
``python -m benchmark pretrain`` runs it and exports the weights and their provenance into the
package (:mod:`benchmark.codesign.utility.clean` loads them).
"""

from __future__ import annotations

import argparse
import logging
import json
import math
import os
import shutil
import time
from pathlib import Path
from typing import Any

import numpy as np
import torch
import torch.nn.functional as F
from safetensors.torch import load_file, save_file
from tqdm.auto import tqdm

from benchmark.store.cache import (atomic_write_text, cache_root, config_hash, discard, read_verified_checkpoint, read_verified_json,
                                   read_verified_tensors, write_verified_checkpoint, write_verified_json, write_verified_tensors)
from benchmark.store.provenance import git_commit, package_versions
from benchmark.scenes import CLASS_NAMES, load_scenes
from benchmark.codesign.utility.pretrain_data import RareClassCropSampler
from benchmark.codesign.utility.scoring import IGNORE, confusion_matrix, predict, scores, window_for
from benchmark.codesign.utility.segformer import build_segformer, segment_logits

# Bumped whenever the recipe computes something different, so stale cache entries are not reused.
PRETRAIN_VERSION = 1
PLATEAU_GAIN = 0.01          # sharp val mIoU gained over the last fifth below which training has plateaued
FINAL_LR_FRACTION = 0.01     # the cosine decays to this fraction of the peak learning rate
WEIGHT_DECAY = 0.01
RARE_FRACTION = 0.5          # crops centred on a pixel of a uniformly drawn class
CHECK_SCENES = 2             # val scenes of the small regression check recorded for the test

log = logging.getLogger(__name__)


class PretrainDivergedError(RuntimeError):
    """The loss became NaN or Inf; the last good checkpoint is kept."""


def learning_rate(step: int, steps: int, peak: float, warmup: int) -> float:
    """AdamW learning rate of (0-based) ``step``: linear warmup to ``peak`` over ``warmup`` steps,
    then a cosine from ``peak`` down to ``FINAL_LR_FRACTION * peak`` at ``steps``."""
    if step < warmup:
        return peak * (step + 1) / warmup
    final = FINAL_LR_FRACTION * peak
    progress = (step - warmup) / max(1, steps - warmup)
    return final + (peak - final) * 0.5 * (1.0 + math.cos(math.pi * min(progress, 1.0)))


def recipe(profile: Any, seed: int, scene_set: str) -> dict[str, Any]:
    """Everything the trained weights depend on (hashed for the cache, written in the provenance)."""
    return {"what": "clean-utility-pretrain", "version": PRETRAIN_VERSION, "model": profile.utility_model,
            "scene_set": scene_set, "image_size": list(profile.image_size), "seed": seed,
            "steps": profile.pretrain_steps, "n_train_scenes": profile.pretrain_scenes,
            "crop": list(profile.pretrain_crop), "batch_size": profile.pretrain_batch,
            "rare_class_fraction": RARE_FRACTION,
            "optimizer": {"name": "AdamW", "weight_decay": WEIGHT_DECAY},
            "lr_schedule": {"kind": "linear warmup + cosine", "peak": profile.pretrain_lr,
                            "warmup_steps": profile.pretrain_warmup, "final": FINAL_LR_FRACTION * profile.pretrain_lr}}


def val_protocol(profile: Any, seed: int, scene_set: str, n: int | None = None) -> dict[str, Any]:
    """The sharp val set and sliding window the curve is measured on (the runner's sharp utility row)."""
    window, stride = window_for(profile.image_size, profile.train_crop)
    return {"scene_set": scene_set, "split": "val", "seed": seed, "n_scenes": profile.n_val if n is None else n,
            "image_size": list(profile.image_size), "window": list(window), "stride": list(stride)}


def load_val(protocol: dict[str, Any]) -> tuple[torch.Tensor, torch.Tensor]:
    """(images (N,3,H,W) float32 in [0,1], labels (N,H,W) uint8) of a :func:`val_protocol`."""
    scenes = load_scenes(protocol["scene_set"], "val", protocol["n_scenes"], tuple(protocol["image_size"]),
                         protocol["seed"])
    images = torch.from_numpy(np.stack([s.image for s in scenes])).permute(0, 3, 1, 2).contiguous()
    return images, torch.from_numpy(np.stack([s.labels for s in scenes]))


def evaluate(net: torch.nn.Module, images: torch.Tensor, labels: torch.Tensor, protocol: dict[str, Any],
             device: str = "cpu") -> dict[str, Any]:
    """miou, mean_acc, overall_acc and class_iou ({class name: IoU or None where undefined}) of ``net``."""
    pred = predict(net, images, tuple(protocol["window"]), tuple(protocol["stride"]), batch_size=2, device=device)
    s = scores(confusion_matrix(pred, labels))
    return {"miou": s["miou"], "mean_acc": s["mean_acc"], "overall_acc": s["overall_acc"],
            "class_iou": {name: (None if math.isnan(v) else v) for name, v in zip(CLASS_NAMES, s["class_iou"])}}


def plateau(curve: list[dict[str, Any]], steps: int) -> dict[str, Any]:
    """The plateau criterion on a learning curve (points with "step" and "miou")."""
    if not curve:
        return {"gain_last_fifth": None, "reached": False, "from_step": None}
    start = [p for p in curve if p["step"] <= 0.8 * steps]
    if not start:
        return {"gain_last_fifth": None, "reached": False, "from_step": None}
    gain = curve[-1]["miou"] - start[-1]["miou"]
    return {"gain_last_fifth": gain, "reached": bool(gain < PLATEAU_GAIN and curve[-1]["step"] == steps),
            "from_step": start[-1]["step"], "threshold": PLATEAU_GAIN}


def _load_avg() -> list[float] | None:
    try:
        return [round(v, 2) for v in os.getloadavg()]
    except OSError:
        return None


def train(profile: Any, seed: int, device: str, cache_dir: Path, scene_set: str = "synthetic",
          progress: bool = True) -> tuple[torch.nn.Module, dict[str, Any]]:
    """Pre-train (resuming from the checkpoint) and return (eval-mode net, record); see the module docstring.

    The record holds the recipe, the val protocol, the learning curve, the final scores, the
    plateau verdict, seconds per training step, threads and the load average seen.
    """
    r = recipe(profile, seed, scene_set)
    stem = f"clean-{profile.utility_model}-{config_hash(r)}"
    directory = Path(cache_dir) / "utility"
    weights_path, record_path = directory / f"{stem}.safetensors", directory / f"{stem}.json"
    torch.manual_seed(seed)
    net = build_segformer(profile.utility_model).to(device)
    cached = _load_cached(net, weights_path, record_path)
    if cached is not None:
        return net.eval(), cached

    t_start = time.perf_counter()
    steps, every = profile.pretrain_steps, max(1, profile.pretrain_eval_every)
    protocol = val_protocol(profile, seed, scene_set)
    opt = torch.optim.AdamW(net.parameters(), lr=profile.pretrain_lr, weight_decay=WEIGHT_DECAY)
    checkpoint_path = directory / f"{stem}.checkpoint.pt"
    state: dict[str, Any] = {"step": 0, "curve": [], "train_s": 0.0, "eval_s": 0.0, "scene_s": 0.0,
                             "loads": []}
    present = checkpoint_path.exists()
    saved = read_verified_checkpoint(checkpoint_path)
    if saved is not None:
        net.load_state_dict(saved.pop("net"))
        opt.load_state_dict(saved.pop("opt"))
        state.update(saved)
        log.info("resuming the clean utility pre-training at step %d from %s", state["step"], checkpoint_path)
    elif present:
        log.warning("discarded the corrupt checkpoint %s; the clean utility pre-training restarts from step 0",
                    checkpoint_path)
    t0 = time.perf_counter()
    train_scenes = load_scenes(scene_set, "train", profile.pretrain_scenes, profile.image_size, seed)
    sampler = RareClassCropSampler(train_scenes, profile.pretrain_crop, profile.pretrain_batch, seed, RARE_FRACTION)
    del train_scenes
    val_images, val_labels = load_val(protocol)
    state["scene_s"] += time.perf_counter() - t0

    net.train()
    losses: list[float] = []
    bar = tqdm(range(state["step"], steps), desc="clean utility pre-training", disable=not progress,
               initial=state["step"], total=steps)
    t_train = time.perf_counter()
    for step in bar:
        for group in opt.param_groups:
            group["lr"] = learning_rate(step, steps, profile.pretrain_lr, profile.pretrain_warmup)
        torch.manual_seed(seed * 7919 + step)  # drop-path draws, reproducible across resumes
        x, y = sampler.batch(step, device)
        loss = F.cross_entropy(segment_logits(net, x), y, ignore_index=IGNORE)
        if not torch.isfinite(loss):
            raise PretrainDivergedError(f"clean utility pre-training diverged at step {step} (loss {float(loss)}); "
                                        f"the checkpoint {checkpoint_path} holds the last curve point")
        opt.zero_grad(set_to_none=True)
        loss.backward()
        opt.step()
        losses.append(loss.item())
        bar.set_postfix(ce=f"{losses[-1]:.3f}")
        done = step + 1
        if done % every == 0 or done == steps:
            state["train_s"] += time.perf_counter() - t_train
            t_eval = time.perf_counter()
            point = {"step": done, "train_ce": float(np.mean(losses)) if losses else None,
                     "lr": learning_rate(step, steps, profile.pretrain_lr, profile.pretrain_warmup),
                     **evaluate(net, val_images, val_labels, protocol, device)}
            net.train()
            state["eval_s"] += time.perf_counter() - t_eval
            point["elapsed_s"] = state["train_s"] + state["eval_s"] + state["scene_s"]
            state["curve"].append(point)
            state["loads"].append(_load_avg())
            state["step"] = done
            losses = []
            if progress:
                bar.write(f"step {done}: sharp val mIoU {point['miou']:.3f}, train CE {point['train_ce']:.3f}")
            write_verified_checkpoint(checkpoint_path, {**state, "net": net.state_dict(), "opt": opt.state_dict()})
            t_train = time.perf_counter()
    net.eval()
    curve = state["curve"]
    record = {"recipe": r, "val": protocol, "curve": curve, "final": {k: curve[-1][k] for k in
              ("miou", "mean_acc", "overall_acc", "class_iou")},
              "plateau": plateau(curve, steps),
              "train_class_pixel_fraction": dict(zip(CLASS_NAMES, map(float, sampler.class_pixel_fraction()))),
              "timing": {"seconds_per_step": state["train_s"] / steps, "train_s": state["train_s"],  # resumed parts too
                         "eval_s": state["eval_s"], "scene_generation_s": state["scene_s"],
                         "wall_s": state["train_s"] + state["eval_s"] + state["scene_s"],
                         "threads": torch.get_num_threads(), "load_avg_1_5_15min_at_curve_points": state["loads"],
                         "this_call_s": time.perf_counter() - t_start},
              "device": device, "commit": git_commit(), "packages": package_versions()}
    write_verified_json(record_path, record)
    write_verified_tensors(weights_path, {k: v.detach().cpu().contiguous() for k, v in net.state_dict().items()})
    discard(checkpoint_path)
    return net, record


def _load_cached(net: torch.nn.Module, weights_path: Path, record_path: Path) -> dict[str, Any] | None:
    """The cached record, with the cached weights loaded into ``net``, when both files are intact;
    else None (a corrupt file is reported with its path and removed; ``net`` is left untouched)."""
    if not (weights_path.exists() or record_path.exists()):
        return None
    record = read_verified_json(record_path)
    state = read_verified_tensors(weights_path) if record is not None else None
    if record is None or state is None:  # a corrupt file was reported with its path as it was read
        return None
    net.load_state_dict(state)
    return record


def cached_clean_net(profile: Any, seed: int, device: str, cache_dir: Path, scene_set: str = "synthetic",
                     progress: bool = True) -> torch.nn.Module:
    """The pre-trained clean net from the cache, training it first when absent (eval mode)."""
    return train(profile, seed, device, cache_dir, scene_set, progress)[0]


def export(net: torch.nn.Module, record: dict[str, Any], profile: Any, out_dir: Path, device: str = "cpu",
           dtype: torch.dtype = torch.float16) -> tuple[Path, Path]:
    """Write ``net`` as ``dtype`` safetensors plus its provenance JSON into ``out_dir``; returns both paths.

    The provenance records the file's size and sha256, the sharp val scores of the weights as
    shipped (cast to ``dtype`` and back) beside those of the trained float32 net, and the mIoU of
    the first ``CHECK_SCENES`` val scenes that the package test re-measures.
    """
    from benchmark.codesign.utility.weights_files import file_sha256, provenance_path_for
    out_dir = Path(out_dir)
    out_dir.mkdir(parents=True, exist_ok=True)
    stem = f"segformer-{profile.utility_model}-{profile.name}"
    weights = out_dir / f"{stem}.safetensors"
    state = {k: v.detach().cpu().to(dtype if v.is_floating_point() else v.dtype).contiguous()
             for k, v in net.state_dict().items()}
    tmp = weights.with_name(f".{weights.name}.{os.getpid()}.tmp")
    save_file(state, str(tmp), metadata={"profile": profile.name, "model": profile.utility_model})
    os.replace(tmp, weights)
    shipped = build_segformer(profile.utility_model)
    shipped.load_state_dict({k: v.float() if v.is_floating_point() else v for k, v in load_file(str(weights)).items()})
    shipped = shipped.to(device).eval()
    protocol = record["val"]
    images, labels = load_val(protocol)
    as_shipped = evaluate(shipped, images, labels, protocol, device)
    check_protocol = {**protocol, "n_scenes": CHECK_SCENES}
    check = evaluate(shipped, images[:CHECK_SCENES], labels[:CHECK_SCENES], check_protocol, device)
    body = {
        "file": {"name": weights.name, "bytes": weights.stat().st_size, "sha256": file_sha256(weights),
                 "dtype": str(dtype).removeprefix("torch.")},
        "matches": {"utility_model": profile.utility_model, "image_size": list(profile.image_size),
                    "scene_set": record["recipe"]["scene_set"]},
        "profile": profile.name,
        "commit": record["commit"],
        "recipe": record["recipe"],
        "val": protocol,
        "final_shipped": as_shipped,
        "final_float32": record["final"],
        "plateau": record["plateau"],
        "check": {"val": check_protocol, "miou": check["miou"], "tolerance": 0.005},
        "curve": record["curve"],
        "train_class_pixel_fraction": record["train_class_pixel_fraction"],
        "timing": record["timing"],
        "device": record["device"],
        "packages": record["packages"],
    }
    provenance = provenance_path_for(weights)
    atomic_write_text(provenance, json.dumps(body, indent=1) + "\n")
    return weights, provenance


def build_parser() -> argparse.ArgumentParser:
    """The `pretrain` command's arguments (the same as `python -m benchmark pretrain`'s)."""
    from benchmark.store.profiles import PROFILES
    parser = argparse.ArgumentParser(prog="python -m benchmark pretrain", description=__doc__)
    parser.add_argument("--profile", default="quick", choices=list(PROFILES), help="recipe and val set (default quick)")
    parser.add_argument("--seed", type=int, default=0, help="training seed, and the seed of the val scenes (default 0)")
    parser.add_argument("--out", type=Path, default=None, help="weights folder (default: the package's)")
    parser.add_argument("--dir", type=Path, default=None, help="leaderboard folder (default: the repository's)")
    parser.add_argument("--device", default="cpu", help="cpu (default) or cuda[:N]")
    return parser


def main(argv: list[str] | None = None, args: argparse.Namespace | None = None) -> int:
    """`python -m benchmark pretrain`: train (or resume, or load from the cache), export, chart."""
    from benchmark.results.entries import LEADERBOARD
    from benchmark.results.charts import save_figure
    from benchmark.store.profiles import get_profile
    from benchmark.results.charts.utility_pretrain import pretrain_figure
    args = args or build_parser().parse_args(argv)
    profile = get_profile(args.profile)
    git_commit()  # pinned now, as the code was imported
    net, record = train(profile, args.seed, args.device, cache_root())
    from benchmark.codesign.utility.weights_files import WEIGHTS_DIR
    weights, provenance_file = export(net, record, profile, args.out or WEIGHTS_DIR, args.device)
    body = json.loads(provenance_file.read_text())
    directory = args.dir or LEADERBOARD
    study = directory / "studies" / "utility_pretrain.json"
    study.parent.mkdir(parents=True, exist_ok=True)
    shutil.copyfile(provenance_file, study)
    chart = save_figure(pretrain_figure(body), directory / "charts" / "utility_pretrain.png", dpi=100)
    print(f"wrote {weights} ({body['file']['bytes'] / 1e6:.1f} MB), {provenance_file}, {study}, {chart}")
    print(f"sharp val mIoU {body['final_shipped']['miou']:.4f} as shipped ({body['file']['dtype']}), "
          f"{body['final_float32']['miou']:.4f} in float32; last-fifth gain {body['plateau']['gain_last_fifth']}")
    return 0
