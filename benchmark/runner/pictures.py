"""The pictures of one lens and seed: the sample grid (scene, PSF, sensor, restorations), each
reader's plate gallery and, for a co-designed lens, its training curves, written into the task's folder."""

from __future__ import annotations

import logging
from pathlib import Path

import numpy as np
import torch

import lenses
from benchmark.results.charts.plate_gallery import write_plate_gallery
from benchmark.runner.evaluation import Attacked, Target, gallery_windows
from benchmark.results.plate_scoring import readable
from benchmark.store import cipher
from benchmark.store.cache import atomic_write_bytes, config_hash, read_verified
from benchmark.results.charts.samples import write_sample_grid
from benchmark.results.schema import chain_name

log = logging.getLogger(__name__)


def _first_as_hwc(images: torch.Tensor) -> np.ndarray:
    """The first image of (N,3,H,W) as (H,W,3) in [0,1]."""
    return images[0].permute(1, 2, 0).clamp(0, 1).numpy()


def sample_grid(target: Target, lens: lenses.Lens, out: Attacked, folder: Path) -> str:
    """One PNG: scene, PSF, sensor image and each restorer's output, each with its own PSNR / SSIM
    (computed by the chart for the image shown); its file name."""
    as_hwc = _first_as_hwc
    name = f"samples_{target.lens_name}_seed{target.ctx.seed}.png".replace("/", "_")
    write_sample_grid(folder / name, target.lens_name, lens.psf().detach().cpu().numpy(),
                      as_hwc(target.sharp), as_hwc(target.sensor), {k: as_hwc(v) for k, v in out.restored.items()})
    return name


def plate_gallery(target: Target, out: Attacked, reader: str, folder: Path) -> str | None:
    """The reader's plate gallery over sensor and restored images; its file name (None: nothing to show).

    With plate windows, the gallery shows the windows of `gallery_windows` (the most common size,
    so that its images stack)."""
    if reader not in out.reads:
        return None
    chains = {name: chain_name(name, reader) for name in out.restored if chain_name(name, reader) in out.reads}
    if target.plates is None:
        scenes, pick = target.scenes, list(range(len(target.scenes)))
        images = {"sharp": target.sharp, "sensor": target.sensor, **{n: out.restored[n] for n in chains}}
    else:
        p = target.plates
        pick = gallery_windows(p)  # the only windows the evaluation keeps of each restorer
        scenes = [p.scenes[i] for i in pick]
        images = {name: torch.stack([windows[i] for i in pick]) if pick else torch.empty(0)
                  for name, windows in {"sharp": p.sharp, "sensor": p.sensor,
                                        **{n: out.restored_plates[n] for n in chains}}.items()}
    if not any(readable(pl) for s in scenes for pl in s.plates):
        return None
    reads = {"sensor": [out.reads[reader][i] for i in pick],
             **{n: [out.reads[c][i] for i in pick] for n, c in chains.items()}}
    name = f"plates_{target.lens_name}_{reader}_seed{target.ctx.seed}.png".replace("/", "_")
    write_plate_gallery(images, scenes, reads, folder / name, reader=reader)
    return name


def training_curves(lens: lenses.Lens, seed: int, cache_dir: Path, folder: Path) -> str | None:
    """Copy the co-design run's curves.png (benchmark.codesign.curves) into `folder`; its file name,
    or None for a lens that was not co-designed here.

    The run's folder is found from its training record as the trainer names it:
    ``cache_dir/codesign/{name}-{config_hash(config)}``."""
    record = getattr(lens, "training_record", None)
    if not record or "config" not in record or "name" not in record:
        return None
    source = Path(cache_dir) / "codesign" / f"{record['name']}-{config_hash(record['config'])}" / "curves.png"
    if not source.is_file():
        log.warning("co-design curves of %s not found at %s; the run folder goes without them", lens.name, source)
        return None
    data = read_verified(source)  # a truncated or altered chart is reported and removed, not copied
    if data is None:
        log.warning("co-design curves of %s at %s are missing or corrupt; the run folder goes without them",
                    lens.name, source)
        return None
    name = f"curves_{lens.name}_seed{seed}.png".replace("/", "_")
    atomic_write_bytes(Path(folder) / name, data)
    return name


def copy_picture(source: Path, dest: Path, key: bytes | None = None) -> None:
    """Copy a task's picture (sealed when its task wrote it) to `dest` atomically, after checking it
    against its checksum: a truncated file is never copied, and a full disk leaves no partial one. A
    sealed run's scene pictures are stored encrypted: `key` (``cipher.run_key``) decrypts them."""
    data = read_verified(source)
    if data is None:
        raise RuntimeError(f"picture {source} is missing or does not match its checksum (removed); run again "
                           "to rebuild its task")
    try:
        data = cipher.plain(key, source.name, data)
    except cipher.CipherError:
        raise RuntimeError(f"picture {source} is a sealed run's, encrypted; re-run with its --scene-seeds") from None
    atomic_write_bytes(dest, data)
