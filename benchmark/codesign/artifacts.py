"""Checkpoints and final artifacts of a training run, written atomically and verified on read.

Checkpoints hold tensors, numbers and lists only and are read back with
`torch.load(..., weights_only=True)`; final network weights are safetensors. Every file carries
the cache's SHA-256 sidecar (`benchmark.store.cache`): a missing, truncated or corrupt one is reported
with its path, removed and read as absent, so its producer trains it again. A finished run is a
directory that appears in one `os.replace`, so a reader sees all of it or nothing.
"""

from __future__ import annotations

import logging
import os
import shutil
from pathlib import Path
from typing import Any, TypeVar

import torch

from benchmark.store.cache import (read_verified, read_verified_checkpoint, read_verified_json, read_verified_tensors, write_verified_checkpoint,
                                   write_verified_json, write_verified_tensors)

log = logging.getLogger(__name__)

M = TypeVar("M", bound=torch.nn.Module)


def save_checkpoint(path: Path, state: dict[str, Any]) -> None:
    write_verified_checkpoint(path, state)


def load_checkpoint(path: Path) -> dict[str, Any] | None:
    """The checkpoint at `path`, or None when there is none or it is corrupt (reported with its
    path and removed: training then starts again from step 0)."""
    present = Path(path).exists()
    checkpoint = read_verified_checkpoint(path)
    if checkpoint is None and present:
        log.warning("discarded the corrupt checkpoint %s; training restarts from step 0", path)
    return checkpoint


def save_weights(path: Path, module: torch.nn.Module) -> None:
    write_verified_tensors(path, {k: v.detach().cpu().contiguous() for k, v in module.state_dict().items()})


def load_weights(path: Path, module: M) -> M | None:
    """`module` with the weights at `path`, or None when they are absent, corrupt or do not fit it
    (reported with the path; `module` may then hold some of them: build a fresh one)."""
    state = read_verified_tensors(path)
    if state is None:
        return None
    try:
        module.load_state_dict(state)
    except RuntimeError as exc:  # keys or shapes of another network
        log.warning("cache artifact %s does not fit %s (%s); it will be rebuilt", path, type(module).__name__, exc)
        return None
    return module


def write_json(path: Path, data: Any) -> None:
    write_verified_json(path, data)


def read_json(path: Path) -> Any | None:
    """The JSON at `path`, or None when absent or corrupt (reported with its path and removed)."""
    return read_verified_json(path)


def verified(path: Path) -> bool:
    """Whether the file at `path` matches its checksum (a corrupt one is reported and removed)."""
    return read_verified(path) is not None


def publish_directory(staging: Path, final: Path) -> None:
    """Move a fully written staging directory to `final` in one step."""
    final.parent.mkdir(parents=True, exist_ok=True)
    if final.exists():  # another process finished the same run first: keep theirs
        shutil.rmtree(staging)
        return
    os.replace(staging, final)
