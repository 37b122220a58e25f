"""The sample grid of a lens: scene, PSF, sensor image and each restorer's output with its score."""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np

from benchmark.results.charts import new_figure, save_figure


def _psf_rgb(psf: np.ndarray) -> np.ndarray:
    """(3,K,K) PSF -> RGB image, log-scaled over 3 decades so the rings show."""
    p = np.log10(np.maximum(psf / psf.max(), 1e-3)) / 3.0 + 1.0
    return np.clip(p.transpose(1, 2, 0), 0, 1)


def write_sample_grid(path: Path, lens_name: str, psf: np.ndarray, scene: np.ndarray, sensor: np.ndarray,
                      restored: dict[str, np.ndarray], scores: dict[str, str]) -> Path:
    """One PNG: scene, PSF (log scale), sensor image, then each restorer's output with its score.

    ``psf`` is (3, K, K); ``scene``, ``sensor`` and each ``restored`` image are (H, W, 3) in [0, 1];
    ``scores`` maps a restorer name to the text shown under its image. Returns ``path``.
    """
    panels = [("scene", scene), (f"PSF {psf.shape[-1]}x{psf.shape[-1]} px (log)", _psf_rgb(psf)),
              ("sensor", sensor)]
    panels += [(f"{name}\n{scores.get(name, '')}", img) for name, img in restored.items()]
    cols = min(4, len(panels))
    rows = math.ceil(len(panels) / cols)
    aspect = scene.shape[0] / scene.shape[1]
    fig = new_figure(figsize=(4 * cols, 4 * aspect * rows + 0.6 * rows))
    axes = fig.subplots(rows, cols, squeeze=False)
    for ax in axes.flat:
        ax.axis("off")
    for ax, (title, img) in zip(axes.flat, panels):
        ax.imshow(np.clip(img, 0, 1), interpolation="nearest" if "PSF" in title else "antialiased")
        ax.set_title(title, fontsize=9)
    fig.suptitle(f"lens: {lens_name}", fontsize=11)
    return save_figure(fig, path, dpi=90)
