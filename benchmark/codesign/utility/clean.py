"""The clean utility net every lens fine-tunes: the package's shipped weights, else the cached pre-training.

``benchmark/codesign/utility/weights/`` holds SegFormer weights made by ``python -m benchmark pretrain``
(safetensors) with a provenance JSON beside each (``<stem>.json``): the recipe, the learning
curve, the sharp val scores, and the file's size and sha256. A profile uses shipped weights when
their ``matches`` block equals its utility model, scene size and training scene set; the same
weights then start every seed, as the paper starts every run from one pretrained SegFormer. Any
other profile (or a Cityscapes scene set) gets :func:`benchmark.codesign.utility.pretrain.cached_clean_net`.
Weights files are untrusted input: only safetensors are read, after their size and sha256 match
the provenance.
"""

from __future__ import annotations

import json
from pathlib import Path
from typing import Any

import torch
from safetensors.torch import load_file

from benchmark.codesign.utility.segformer import build_segformer
from benchmark.codesign.utility.weights_files import WEIGHTS_DIR, file_sha256, provenance_path_for

__all__ = ["WEIGHTS_DIR", "CorruptWeightsError", "clean_utility_id", "clean_utility_net", "file_sha256",
           "provenance_path_for", "shipped_for"]


class CorruptWeightsError(ValueError):
    """A weights file does not match its provenance (size, sha256) or cannot be read as safetensors."""


def matches(provenance: dict[str, Any], profile: Any, scene_set: str) -> bool:
    """Whether weights with this provenance are the clean net of ``profile`` on ``scene_set``."""
    m = provenance.get("matches", {})
    return (m.get("utility_model") == profile.utility_model and list(m.get("image_size", [])) ==
            list(profile.image_size) and m.get("scene_set") == scene_set)


def shipped_for(profile: Any, scene_set: str = "synthetic", directory: Path = WEIGHTS_DIR) -> Path | None:
    """The shipped weights file for (profile, scene set), or None when none matches."""
    for record in sorted(Path(directory).glob("*.json")):
        provenance = json.loads(record.read_text())
        if matches(provenance, profile, scene_set):
            return record.with_name(provenance["file"]["name"])
    return None


def load_verified(weights: Path, variant: str) -> torch.nn.Module:
    """SegFormer ``variant`` (float32, eval mode, CPU) with the weights of ``weights``, checked first.

    Raises:
        CorruptWeightsError: the provenance beside the file is missing, or the file is missing, has
            another size or sha256 than recorded, is no readable safetensors, or does not fit the model.
    """
    weights = Path(weights)
    provenance_file = provenance_path_for(weights)
    if not provenance_file.is_file():
        raise CorruptWeightsError(f"utility weights {weights}: no provenance {provenance_file} beside them; "
                                  "re-create both with `python -m benchmark pretrain`")
    expected = json.loads(provenance_file.read_text())["file"]
    if not weights.is_file():
        raise CorruptWeightsError(f"utility weights {weights} are missing (named by {provenance_file})")
    size = weights.stat().st_size
    if size != expected["bytes"]:
        raise CorruptWeightsError(f"utility weights {weights} are corrupt: {size} bytes, the provenance records "
                                  f"{expected['bytes']}; re-create them with `python -m benchmark pretrain`")
    digest = file_sha256(weights)
    if digest != expected["sha256"]:
        raise CorruptWeightsError(f"utility weights {weights} are corrupt: sha256 {digest}, the provenance records "
                                  f"{expected['sha256']}; re-create them with `python -m benchmark pretrain`")
    net = build_segformer(variant)
    try:
        state = load_file(str(weights))
        net.load_state_dict({k: v.float() if v.is_floating_point() else v for k, v in state.items()})
    except Exception as exc:  # safetensors and torch raise several types for a bad file
        raise CorruptWeightsError(f"utility weights {weights} cannot be loaded into SegFormer-{variant}: "
                                  f"{exc}") from exc
    return net.eval()


def clean_utility_net(profile: Any, seed: int, device: str, cache_dir: Path, scene_set: str = "synthetic",
                      progress: bool = True) -> torch.nn.Module:
    """The clean utility net of (profile, seed) on ``device``, in eval mode.

    Shipped weights matching the profile (the same for every seed), else the cached pre-training
    of :mod:`benchmark.codesign.utility.pretrain` (trained now when absent).
    """
    shipped = shipped_for(profile, scene_set)
    if shipped is not None:
        return load_verified(shipped, profile.utility_model).to(device)
    from benchmark.codesign.utility.pretrain import cached_clean_net
    return cached_clean_net(profile, seed, device, cache_dir, scene_set, progress)


def clean_utility_id(profile: Any, seed: int, scene_set: str = "synthetic") -> str:
    """What :func:`clean_utility_net` returns for these arguments, for the cache keys of runs that
    fine-tune it: ``shipped:<sha256 recorded for the file>``, else ``recipe:<hash of the pre-training recipe>``."""
    shipped = shipped_for(profile, scene_set)
    if shipped is not None:
        return "shipped:" + json.loads(provenance_path_for(shipped).read_text())["file"]["sha256"]
    from benchmark.store.cache import config_hash
    from benchmark.codesign.utility.pretrain import recipe
    return "recipe:" + config_hash(recipe(profile, seed, scene_set))
