"""Trained attacker weights shipped inside the package (``attacks/weights/``), found by their cache key.

A lens-independent trained attacker (``nafnet-generic``) is the same network for every lens of a
profile and seed, so the package may carry it, as the paper's attacker came with pretrained GoPro
weights: a fresh machine then loads it instead of training it. Each file ``<name>.safetensors`` has
its provenance ``<name>.json`` beside it: ``kind`` (the attacker), ``key`` (the exact configuration
key the attacker would cache the weights under: budget, training-data fingerprint, seed), ``size`` and
``sha256`` of the file, and how it was made (commit, command, seconds, a check score). A file is used
only when its ``key`` equals the attacker's key, so a change of budget, scenes or seed trains again
instead of loading weights made for something else. Files are read only as safetensors, after their
size and sha256 match; a mismatch raises ``ShippedWeightsError`` naming the file (a damaged install is
reported, not silently retrained around).

Made by ``python -m benchmark pretrain-attacker nafnet-generic`` (``benchmark.attack_weights``).
"""

from __future__ import annotations

import dataclasses
import hashlib
import json
from collections.abc import Mapping
from pathlib import Path
from typing import Any

__all__ = ["SHIPPED_DIR", "Shipped", "ShippedWeightsError", "find_shipped", "key_text", "read_checked",
           "write_shipped"]

SHIPPED_DIR = Path(__file__).resolve().parent / "weights"


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
    """The shipped weights of attacker ``kind`` made under exactly ``key``, verified; None if none match.

    Raises:
        ShippedWeightsError: a matching provenance whose weights file is missing, of another size, or
            of another sha256; or a provenance of ``kind`` that cannot be read.
    """
    folder = SHIPPED_DIR if directory is None else Path(directory)
    wanted = key_text(key)
    for prov_path in sorted(folder.glob(f"{kind}-*.json")):
        prov = _read_provenance(prov_path)
        if prov["kind"] != kind or key_text(prov["key"]) != wanted:
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
