"""Co-design runs shipped inside the package (``benchmark/codesign/shipped/``), found by their folder name.

A finished co-design run is cached as the folder ``<name>-<config hash>`` (``CoDesign.directory``).
The package may carry such a folder, so that a fresh machine loads the lens the README's command runs
(``gp``, quick profile, seed 0) instead of spending the co-design on it: ``CoDesign.load`` installs
the shipped folder into the cache when the cache has none of that name. The folder name holds the
hash of the run's whole configuration (scheme, start lens, seed, profile fields, clean net), so any
change of those co-designs again instead of loading a lens made for something else.

Each shipped folder holds the run's published files and ``shipped.json``: the configuration, each
file's size and sha256, and how it was made (commit, command, machine, training seconds) with a
check (the lens's own utility net scored on a few val scenes through the lens) that
``tests/benchmark/codesign/test_shipped_lens.py`` re-measures. A file whose size or sha256 differs
raises ``ShippedLensError`` naming it (a damaged install is reported, not trained around).

Made by ``python -m benchmark ship-lens NAME`` (``benchmark.publish.ship_lens``).
"""

from __future__ import annotations

import hashlib
import json
import logging
import os
import shutil
import uuid
from collections.abc import Mapping
from pathlib import Path
from typing import Any

from attacks.training.shipped_weights import key_text, read_checked
from benchmark.store.cache import write_verified
from benchmark.codesign.artifacts import publish_directory
from benchmark.codesign.curves import PUBLISHED_FILES

__all__ = ["SHIPPED_DIR", "ShippedLensError", "install_shipped", "ship_run", "shipped_provenance"]

log = logging.getLogger(__name__)

SHIPPED_DIR = Path(__file__).resolve().parent / "shipped"
RUN_FILES = ("lens.toml", "utility.safetensors", "adversary.safetensors", "record.json") + PUBLISHED_FILES
PROVENANCE = "shipped.json"


class ShippedLensError(ValueError):
    """A shipped co-design folder is malformed, or one of its files does not match its provenance."""


def shipped_provenance(folder_name: str, directory: Path | None = None) -> dict[str, Any] | None:
    """The provenance of the shipped run ``folder_name``, or None when the package has none.

    Raises:
        ShippedLensError: the folder exists but its provenance is unreadable or lacks a field.
    """
    path = (SHIPPED_DIR if directory is None else Path(directory)) / folder_name / PROVENANCE
    if not path.is_file():
        return None
    try:
        prov = json.loads(path.read_text())
    except (OSError, ValueError) as exc:
        raise ShippedLensError(f"shipped co-design provenance {path}: unreadable ({exc}); reinstall the package "
                               "or remake it with `python -m benchmark ship-lens`") from exc
    missing = [k for k in ("config", "files", "made") if k not in prov] if isinstance(prov, dict) else ["all"]
    if missing:
        raise ShippedLensError(f"shipped co-design provenance {path}: missing fields {missing}; expected config, "
                               "files and made")
    return prov


def install_shipped(folder: Path, config: Mapping[str, Any], directory: Path | None = None) -> bool:
    """Install the shipped run named ``folder.name`` as the cache folder ``folder``; False if none is shipped.

    Every file is checked against the provenance before anything reaches the cache, and the folder
    appears in one step (``publish_directory``), each file with the cache's checksum sidecar, so
    ``CoDesign.load`` reads it as if this machine had trained it.

    Raises:
        ShippedLensError: the shipped configuration is not ``config`` (a folder renamed by hand), or a
            file is missing or differs in size or sha256 from the provenance.
    """
    source = (SHIPPED_DIR if directory is None else Path(directory)) / folder.name
    prov = shipped_provenance(folder.name, directory)
    if prov is None:
        return False
    if key_text(prov["config"]) != key_text(config):
        raise ShippedLensError(f"shipped co-design {source}: its configuration is not the run's, though the "
                               "folder names match; reinstall the package or remake it with `python -m benchmark "
                               "ship-lens`")
    contents = {name: read_checked(source / name, expected["bytes"], expected["sha256"], "shipped co-design file",
                                   ShippedLensError)
                for name, expected in prov["files"].items()}
    staging = folder.with_name(f"{folder.name}.staging-shipped-{os.getpid()}-{uuid.uuid4().hex[:8]}")
    shutil.rmtree(staging, ignore_errors=True)
    staging.mkdir(parents=True)
    for name, data in contents.items():
        write_verified(staging / name, data)
    (staging / PROVENANCE).write_text(json.dumps(prov, indent=1, sort_keys=True) + "\n")
    publish_directory(staging, folder)
    made = prov["made"]
    log.info("%s: co-design shipped with the package (commit %s, %s s of training on %s); a fresh co-design "
             "runs for any other configuration", folder.name, str(made.get("commit"))[:12], made.get("train_s"),
             made.get("machine"))
    return True


def ship_run(run_dir: Path, config: Mapping[str, Any], made: Mapping[str, Any], directory: Path | None = None) -> Path:
    """Copy the finished run folder ``run_dir`` into ``directory`` (default ``SHIPPED_DIR``) with its provenance.

    Raises:
        ShippedLensError: a file of the run is missing.
    """
    target = (SHIPPED_DIR if directory is None else Path(directory)) / Path(run_dir).name
    files = {}
    for name in RUN_FILES:
        path = Path(run_dir) / name
        if not path.is_file():
            if name == "adversary.safetensors" and not config.get("adversary"):
                continue
            raise ShippedLensError(f"co-design run {run_dir} has no {name}; finish the run first")
        data = path.read_bytes()
        files[name] = (data, {"bytes": len(data), "sha256": hashlib.sha256(data).hexdigest()})
    shutil.rmtree(target, ignore_errors=True)
    target.mkdir(parents=True)
    for name, (data, _) in files.items():
        (target / name).write_bytes(data)
    provenance = {"config": json.loads(json.dumps(config)), "files": {n: meta for n, (_, meta) in files.items()},
                  "made": dict(made)}
    (target / PROVENANCE).write_text(json.dumps(provenance, indent=1, sort_keys=True) + "\n")
    return target
