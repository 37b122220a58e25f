"""Where the shipped utility weights live and how their files are named and fingerprinted (shared by
the pre-training that writes them and the loader that verifies them)."""

from __future__ import annotations

import hashlib
from pathlib import Path

WEIGHTS_DIR = Path(__file__).resolve().parent / "weights"


def provenance_path_for(weights: Path) -> Path:
    """``x.safetensors`` -> ``x.json`` beside it."""
    return Path(weights).with_suffix(".json")


def file_sha256(path: Path) -> str:
    h = hashlib.sha256()
    with open(path, "rb") as f:
        for block in iter(lambda: f.read(1 << 20), b""):
            h.update(block)
    return h.hexdigest()
