"""Checkpoints and final artifacts of a training run, written atomically.

Checkpoints hold tensors, numbers and lists only and are read back with
`torch.load(..., weights_only=True)`; final network weights are safetensors. A finished run is
a directory that appears in one `os.replace`, so a reader sees all of it or nothing.
"""

from __future__ import annotations

import io
import json
import os
import shutil
from pathlib import Path
from typing import Any

import torch
from safetensors.torch import load_file, save_file

from benchmark.cache import atomic_write_bytes


def save_checkpoint(path: Path, state: dict[str, Any]) -> None:
    buffer = io.BytesIO()
    torch.save(state, buffer)
    atomic_write_bytes(path, buffer.getvalue())


def load_checkpoint(path: Path) -> dict[str, Any] | None:
    """The checkpoint at `path`, or None when there is none."""
    if not Path(path).is_file():
        return None
    return torch.load(path, map_location="cpu", weights_only=True)


def save_weights(path: Path, module: torch.nn.Module) -> None:
    state = {k: v.detach().cpu().contiguous() for k, v in module.state_dict().items()}
    save_file(state, str(path))


def load_weights(path: Path, module: torch.nn.Module) -> torch.nn.Module:
    module.load_state_dict(load_file(str(path)))
    return module


def publish_directory(staging: Path, final: Path) -> None:
    """Move a fully written staging directory to `final` in one step."""
    final.parent.mkdir(parents=True, exist_ok=True)
    if final.exists():  # another process finished the same run first: keep theirs
        shutil.rmtree(staging)
        return
    os.replace(staging, final)


def write_json(path: Path, data: Any) -> None:
    atomic_write_bytes(path, json.dumps(data, indent=1, default=float).encode())
