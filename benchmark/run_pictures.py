"""The pictures of one lens and seed: the sample grid (scene, PSF, sensor, restorations) and each
reader's plate gallery, written into the task's folder."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import torch

import lenses
from benchmark.charts.plate_gallery import write_plate_gallery
from benchmark.evaluation import Attacked, Target
from benchmark.plate_scoring import readable
from benchmark.charts.samples import write_sample_grid
from benchmark.schema import chain_name


def _first_as_hwc(images: torch.Tensor) -> np.ndarray:
    """The first image of (N,3,H,W) as (H,W,3) in [0,1]."""
    return images[0].permute(1, 2, 0).clamp(0, 1).numpy()


def sample_grid(target: Target, lens: lenses.Lens, out: Attacked, folder: Path) -> str:
    """One PNG: scene, PSF, sensor image and each restorer's output with its score; its file name."""
    scores = {r.attack: f"PSNR {r.metrics['psnr_db']:.2f} dB, SSIM {r.metrics['ssim']:.3f}" for r in out.rows
              if r.attack == r.restorer and "psnr_db" in r.metrics and "ssim" in r.metrics}
    as_hwc = _first_as_hwc
    name = f"samples_{target.lens_name}_seed{target.ctx.seed}.png".replace("/", "_")
    write_sample_grid(folder / name, target.lens_name, lens.psf().detach().cpu().numpy(),
                      as_hwc(target.sharp), as_hwc(target.sensor), {k: as_hwc(v) for k, v in out.restored.items()},
                      scores)
    return name


def plate_gallery(target: Target, out: Attacked, reader: str, folder: Path) -> str | None:
    """The reader's plate gallery over sensor and restored images; its file name (None: nothing to show)."""
    if reader not in out.reads or not any(readable(pl) for s in target.scenes for pl in s.plates):
        return None
    chains = {name: chain_name(name, reader) for name in out.restored if chain_name(name, reader) in out.reads}
    images = {"sharp": target.sharp, "sensor": target.sensor, **{n: out.restored[n] for n in chains}}
    reads = {"sensor": out.reads[reader], **{n: out.reads[c] for n, c in chains.items()}}
    name = f"plates_{target.lens_name}_{reader}_seed{target.ctx.seed}.png".replace("/", "_")
    write_plate_gallery(images, target.scenes, reads, folder / name)
    return name
