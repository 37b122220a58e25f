"""Utility model size study: SegFormer variants each trained to its plateau, scored on the same scenes.

Each variant is pre-trained on sharp scenes exactly as a profile's clean utility net
(:func:`benchmark.codesign.utility.pretrain.train`: the profile's ``pretrain_*`` recipe, its learning curve
and plateau verdict; cached by the recipe's hash) and then scored by the runner's segmenter on the
profile's sharp val scenes: mIoU, mean and overall accuracy with their scene-bootstrap 95 %
intervals, per-class IoU, parameters, inference images/s, and the seconds training took (from the
training record: pure training steps, threads and load average as measured when it ran). Every
smaller variant is compared with the largest on the same scenes (paired scene bootstrap of the
pooled mIoU): "the larger model segments better" holds, does not hold, or cannot be told at this
sample size. That decides whether the suite's utility model is larger than the embedded scenes
need, where every model has converged rather than at a fixed tiny budget.

A variant may name its training crop, ``"tiny@256"`` (square, pixels): the same recipe with
``pretrain_crop`` changed, compared with the same model at the profile's crop (the crop lever:
does more context per crop lift the plateau?).
"""

from __future__ import annotations

import dataclasses
import json
import os
from collections.abc import Sequence
from pathlib import Path
from typing import Any

import numpy as np
import torch

from benchmark.results import stats
from benchmark.store.cache import atomic_write_text, cache_root
from benchmark.runner.intervals import pooled_score_interval
from benchmark.store.profiles import Profile
from benchmark.store.provenance import provenance
from benchmark.runner.config import RunConfig
from benchmark.scenes import CLASS_NAMES, load_scenes
from benchmark.runner.sensing import to_tensor
from benchmark.codesign.utility import clean, pretrain
from benchmark.runner.utility_measure import utility_scores
from benchmark.codesign.utility.scoring import scores

VARIANTS = ("tiny", "b0-narrow", "b0")
SCORES = ("miou", "mean_acc", "overall_acc")


def _pooled_miou(strata: Sequence[np.ndarray]) -> float:
    return float(np.mean([scores(torch.from_numpy(s.sum(axis=0)))["miou"] for s in strata]))


def predicted_as(confusion: np.ndarray, top: int = 3) -> dict[str, dict[str, float]]:
    """Per labelled class, the ``top`` classes its pixels were predicted as, with their fractions (where
    a class's pixels go: what caps its IoU), from a pooled (C, C) confusion matrix (rows = truth)."""
    out = {}
    for i, name in enumerate(CLASS_NAMES):
        total = confusion[i].sum()
        if total > 0:
            order = np.argsort(-confusion[i], kind="stable")[:top]
            out[name] = {CLASS_NAMES[j]: float(confusion[i, j] / total) for j in order if confusion[i, j] > 0}
    return out


def parse_variant(spec: str, profile: Profile) -> Profile:
    """The profile a variant spec trains with: ``"b0"`` (the profile's crop) or ``"b0@256"`` (256 x 256 crops)."""
    model, _, crop = spec.partition("@")
    if not crop:
        return dataclasses.replace(profile, utility_model=model)
    if not crop.isdigit() or int(crop) < 1:
        raise ValueError(f"utility-size variant {spec!r}: the crop after '@' must be a positive whole number of "
                         f"pixels, e.g. {model}@256")
    size = int(crop)
    if size > min(profile.image_size):
        raise ValueError(f"utility-size variant {spec!r}: crop {size} exceeds the scenes {tuple(profile.image_size)}")
    return dataclasses.replace(profile, utility_model=model, pretrain_crop=(size, size))


def _compare(better: np.ndarray, other: np.ndarray, claim: str, seed: int) -> dict[str, Any]:
    comparison = stats.stratified_paired_bootstrap([better], [other], _pooled_miou, seed=seed)
    return {"claim": claim, "verdict": stats.verdict(comparison, "greater").text,
            "difference": comparison.difference, "interval": [comparison.low, comparison.high],
            "p_value": comparison.p_value, "n_scenes": comparison.n}


def _shipped_check(net: torch.nn.Module, images: torch.Tensor, scenes: list, cfg: RunConfig, profile: Profile,
                   seed: int) -> dict[str, Any] | None:
    """The package's shipped clean weights for ``profile`` (made by the same recipe), scored on the same
    scenes, and how far the weights just trained lie from them (largest absolute difference after
    rounding to the shipped float16): whether the shipped file is reproduced by its recipe here."""
    path = clean.shipped_for(profile)
    if path is None:
        return None
    shipped = clean.load_verified(path, profile.utility_model)
    with torch.no_grad():
        metrics, per_scene = utility_scores(shipped, images, scenes, cfg)
    ours = dict(net.state_dict())
    difference = max(float((ours[k].half().float() - v).abs().max()) for k, v in shipped.state_dict().items()
                     if v.is_floating_point())
    return {"file": path.name, "miou": metrics["miou"],
            "miou_interval": list(pooled_score_interval(per_scene, "miou", seed)),
            "max_abs_weight_difference": difference}


def measure(profile: Profile, variants: tuple[str, ...] = VARIANTS, seed: int = 0,
            cache_dir: Path | None = None, progress: bool = False) -> list[dict[str, Any]]:
    """One record per variant (see the module docstring), in the order given. Every record of the
    profile's crop but the last carries ``vs_largest``, its paired comparison with the last such
    variant; a record with its own crop carries ``vs_profile_crop``, its comparison with the same
    model at the profile's crop, where that was measured too."""
    cache_dir = Path(cache_dir or cache_root())
    scenes = load_scenes("synthetic", "val", profile.n_val, profile.image_size, seed)
    images = to_tensor(scenes)
    records: list[dict[str, Any]] = []
    confusions: list[np.ndarray] = []
    for variant in variants:
        p = parse_variant(variant, profile)
        net, trained = pretrain.train(p, seed, "cpu", cache_dir, progress=progress)
        cfg = RunConfig(lenses=[], attacks=[], scenes="synthetic", profile=p, seeds=[seed], cache_dir=cache_dir)
        with torch.no_grad():
            metrics, per_scene = utility_scores(net, images, scenes, cfg)
        confusions.append(per_scene.double().numpy())
        timing = trained["timing"]
        records.append({
            "variant": variant, "model": p.utility_model, "pretrain_crop": list(p.pretrain_crop),
            "params": sum(q.numel() for q in net.parameters()),
            **{name: metrics[name] for name in SCORES},
            "intervals": {name: list(pooled_score_interval(per_scene, name, seed)) for name in SCORES},
            "class_iou": {name: metrics.get(f"iou_{name}") for name in CLASS_NAMES},
            "predicted_as": predicted_as(per_scene.sum(dim=0).double().numpy()),
            "images_per_s": metrics["images_per_s"],
            "train_s": timing["train_s"], "seconds_per_step": timing["seconds_per_step"],
            "train_threads": timing["threads"], "train_load_avg": timing["load_avg_1_5_15min_at_curve_points"],
            "steps": trained["recipe"]["steps"], "plateau": trained["plateau"],
            "curve": [{"step": c["step"], "miou": c["miou"], "elapsed_s": c["elapsed_s"]} for c in trained["curve"]],
            "curve_val_scenes": trained["val"]["n_scenes"], "train_commit": trained["commit"],
        })
        if "@" not in variant and variant == profile.utility_model:
            records[-1]["shipped"] = _shipped_check(net, images, scenes, cfg, p, seed)
    at_profile_crop = [i for i, v in enumerate(variants) if "@" not in v]
    if at_profile_crop:
        last = at_profile_crop[-1]
        for i in at_profile_crop[:-1]:
            records[i]["vs_largest"] = _compare(confusions[last], confusions[i], f"{variants[last]} segments better "
                                                f"than {variants[i]} (mIoU)", seed)
    for i, variant in enumerate(variants):
        model = variant.partition("@")[0]
        if "@" in variant and model in variants:
            j = variants.index(model)
            records[i]["vs_profile_crop"] = _compare(confusions[i], confusions[j], f"{variant} segments better than "
                                                     f"{model} at the profile's crop (mIoU)", seed)
    return records


def run(path: Path, profile: Profile, seed: int = 0, variants: tuple[str, ...] = VARIANTS,
        progress: bool = True) -> Path:
    """Measure and write the study JSON (records, profile, threads, load and provenance) to ``path``."""
    records = measure(profile, variants, seed=seed, progress=progress)
    body = {"study": "utility_size", "profile": profile.to_dict(), "seed": seed,
            "threads": torch.get_num_threads(), "load_avg_at_end": list(os.getloadavg()),
            "records": records, "provenance": provenance("cpu")}
    atomic_write_text(path, json.dumps(body, indent=1, sort_keys=True) + "\n")
    return path
