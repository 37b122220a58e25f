"""Trained attacker weights shipped inside the package (``attacks/weights/``), found by their cache key.

A lens-independent trained attacker (``nafnet-generic``) is the same network for every lens of a
profile and seed, so the package may carry it, as the paper's attacker came with pretrained GoPro
weights: a fresh machine then loads it instead of training it. Each file ``<name>.safetensors`` has
its provenance ``<name>.json`` beside it: ``kind`` (the attacker), ``key`` (the exact configuration
key the attacker would cache the weights under: budget, training-data fingerprint, seed), ``size`` and
``sha256`` of the file, and how it was made (commit, command, seconds, a check score). A file is used
only when its ``key`` equals the attacker's key, so a change of budget, scenes or seed trains again
instead of loading weights made for something else. The one tolerant field is the training data
(``data``: the sha256 of its bytes and a numeric ``summary``): simulated sensor images differ between
CPUs by float rounding (measured: 0.009 % of the known-pairs pixels of the quick gp lens move by one
10-bit ADC step between AVX2 and AVX-512 kernels), which changes every byte hash; data whose summaries
agree within ``SUMMARY_ATOL`` is the same data (``same_data``); another sensor-noise draw on the same
scenes moves the median summary entry by 1.2e-4 and 95 % of them beyond ``SUMMARY_ATOL``.

Files are read only as safetensors, after their size and sha256 match; a mismatch raises
``ShippedWeightsError`` naming the file (a damaged install is reported, not silently retrained around).

Made by ``python -m benchmark pretrain-attacker nafnet-generic`` (``benchmark.publish.ship_attacker``).
"""

from __future__ import annotations

import dataclasses
import hashlib
import json
from collections.abc import Mapping
from pathlib import Path
from typing import Any

import torch
from torch import Tensor

__all__ = ["SHIPPED_DIR", "SUMMARY_ATOL", "Shipped", "ShippedWeightsError", "data_summary", "find_shipped",
           "key_text", "read_checked", "same_data", "write_shipped"]

SHIPPED_DIR = Path(__file__).resolve().parents[1] / "weights"  # attacks/weights/
# Largest difference of two summaries of the same data. One ADC step (1/1023) on 0.01 % of the pixels
# moves a quadrant mean (64 x 64 pixels at 128 px) by about 1e-7 (measured: <= 1e-6, the rounding).
SUMMARY_ATOL = 1e-5


class ShippedWeightsError(ValueError):
    """A shipped weights file or its provenance is missing, malformed or does not match its sha256."""


@dataclasses.dataclass(frozen=True)
class Shipped:
    """Verified bytes of one shipped weights file and its provenance."""

    path: Path
    data: bytes
    provenance: dict[str, Any]

    def describe(self) -> dict[str, Any]:
        """What a result row records about the weights: file name, sha256, the commit that made them."""
        made = self.provenance.get("made", {})
        return {"file": self.path.name, "sha256": self.provenance["sha256"], "commit": made.get("commit")}


def key_text(key: Mapping[str, Any]) -> str:
    """Canonical JSON of a configuration key (tuples and lists alike, keys sorted)."""
    return json.dumps(json.loads(json.dumps(key)), sort_keys=True)


def data_summary(*tensors: Tensor) -> list[float]:
    """Per image and channel: the means of the four quadrants and the standard deviation (6 decimals).

    Args:
        tensors: (N, C, H, W) float tensors, H and W even.
    """
    values = []
    for t in tensors:
        x = t.detach().double().cpu()
        n, c, h, w = x.shape
        quads = x.reshape(n, c, 2, h // 2, 2, w // 2).mean(dim=(3, 5)).reshape(n, c, 4)
        values.append(torch.cat([quads, x.reshape(n, c, -1).std(dim=2, keepdim=True)], dim=2).flatten())
    return [round(v, 6) for v in torch.cat(values).tolist()]


def same_data(a: Any, b: Any) -> bool:
    """Whether two ``data`` fields of a key name the same training data: equal sha256 or equal text, or
    ``summary`` lists of one length that agree within ``SUMMARY_ATOL``. A field that describes its data
    instead (no sha256, no summary: e.g. which scenes of which split) must be equal as text."""
    fingerprinted = isinstance(a, Mapping) and isinstance(b, Mapping) and any(
        k in d for d in (a, b) for k in ("sha256", "summary"))
    if not fingerprinted:
        return key_text({"d": a}) == key_text({"d": b})
    if a.get("sha256") is not None and a.get("sha256") == b.get("sha256"):
        return True
    sa, sb = a.get("summary"), b.get("summary")
    if not isinstance(sa, list) or not isinstance(sb, list) or len(sa) != len(sb) or not sa:
        return False
    return max(abs(float(x) - float(y)) for x, y in zip(sa, sb)) <= SUMMARY_ATOL


def _read_provenance(path: Path) -> dict[str, Any]:
    try:
        prov = json.loads(path.read_text())
    except (OSError, ValueError) as exc:
        raise ShippedWeightsError(f"shipped weights provenance {path}: unreadable ({exc}); reinstall the package "
                                  "or remake it with `python -m benchmark pretrain-attacker`") from exc
    missing = [k for k in ("kind", "key", "size", "sha256") if k not in prov] if isinstance(prov, dict) else ["all"]
    if missing:
        raise ShippedWeightsError(f"shipped weights provenance {path}: missing fields {missing}; expected kind, key, "
                                  "size and sha256")
    return prov


def read_checked(path: Path, size: int, sha256: str, what: str,
                 error: type[ValueError] = ShippedWeightsError) -> bytes:
    """The bytes of the shipped file ``path``, which its provenance says are ``size`` bytes with ``sha256``.

    Raises:
        error: the file is missing or unreadable, or has another size or sha256 (the message names
            ``what`` and the path, and says to reinstall the package).
    """
    try:
        data = Path(path).read_bytes()
    except OSError as exc:
        raise error(f"{what} {path}: missing or unreadable ({exc}); reinstall the package") from exc
    digest = hashlib.sha256(data).hexdigest()
    if len(data) != size or digest != sha256:
        raise error(f"{what} {path}: {len(data)} bytes with sha256 {digest[:12]}..., its provenance says {size} "
                    f"bytes, {str(sha256)[:12]}...; the file is damaged: reinstall the package")
    return data


def find_shipped(kind: str, key: Mapping[str, Any], directory: Path | None = None) -> Shipped | None:
    """The shipped weights of attacker ``kind`` made under ``key`` (exactly, but for ``same_data``), verified;
    None if none match.

    Raises:
        ShippedWeightsError: a matching provenance whose weights file is missing, of another size, or
            of another sha256; or a provenance of ``kind`` that cannot be read.
    """
    folder = SHIPPED_DIR if directory is None else Path(directory)

    def all_but_data(k: Mapping[str, Any]) -> str:
        return key_text({name: value for name, value in k.items() if name != "data"})

    wanted = all_but_data(key)
    for prov_path in sorted(folder.glob(f"{kind}-*.json")):
        prov = _read_provenance(prov_path)
        shipped_key = prov["key"] if isinstance(prov["key"], dict) else {}
        if (prov["kind"] != kind or all_but_data(shipped_key) != wanted
                or not same_data(shipped_key.get("data"), key.get("data"))):
            continue
        weights = prov_path.with_suffix(".safetensors")
        data = read_checked(weights, prov["size"], prov["sha256"], f"shipped weights (described by {prov_path.name})")
        return Shipped(weights, data, prov)
    return None


def write_shipped(name: str, kind: str, key: Mapping[str, Any], data: bytes, made: dict[str, Any],
                  directory: Path | None = None) -> Path:
    """Write ``<name>.safetensors`` and its provenance into ``directory`` (default ``SHIPPED_DIR``)."""
    folder = SHIPPED_DIR if directory is None else Path(directory)
    folder.mkdir(parents=True, exist_ok=True)
    weights = folder / f"{name}.safetensors"
    provenance = {"kind": kind, "key": json.loads(key_text(key)), "size": len(data),
                  "sha256": hashlib.sha256(data).hexdigest(), "made": made}
    tmp = weights.with_suffix(".safetensors.tmp")
    tmp.write_bytes(data)
    tmp.replace(weights)
    weights.with_suffix(".json").write_text(json.dumps(provenance, indent=1, sort_keys=True) + "\n")
    return weights
