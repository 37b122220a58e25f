"""The sample grid of a lens: scene, PSF, sensor image and each restorer's output, each scored as the
image shown (its own PSNR and SSIM against the scene), never with the run's means."""

from __future__ import annotations

import math
import textwrap
from pathlib import Path

import numpy as np
import torch
from matplotlib.figure import Figure

from benchmark.results.charts import new_figure, save_figure
from benchmark.results.metrics import psnr, ssim

DPI = 90
FONT_PT, NOTE_PT = 11.0, 10.0
_CELL_IN = 3.2  # a panel's width: four across are about 1150 px, shown about 1000 px wide


def _psf_rgb(psf: np.ndarray) -> np.ndarray:
    """(3,K,K) PSF -> RGB image, log-scaled over 3 decades so the rings show."""
    p = np.log10(np.maximum(psf / psf.max(), 1e-3)) / 3.0 + 1.0
    return np.clip(p.transpose(1, 2, 0), 0, 1)


def image_scores(image: np.ndarray, scene: np.ndarray) -> tuple[float, float] | None:
    """(PSNR dB, SSIM) of one (H, W, 3) image in [0, 1] against the scene, as the run scores a restorer
    (benchmark.results.metrics); None when the image is too small for SSIM's window."""
    x = torch.from_numpy(np.ascontiguousarray(np.clip(image, 0, 1), dtype=np.float32)).permute(2, 0, 1)[None]
    ref = torch.from_numpy(np.ascontiguousarray(np.clip(scene, 0, 1), dtype=np.float32)).permute(2, 0, 1)[None]
    try:
        return float(psnr(x, ref)[0]), float(ssim(x, ref)[0])
    except ValueError:
        return None


def _score_text(scores: tuple[float, float] | None) -> str:
    if scores is None:
        return ""
    db, s = scores
    return f"PSNR {db:.2f} dB, SSIM {s:.3f}" if math.isfinite(db) else f"identical (SSIM {s:.3f})"


def sample_grid_figure(lens_name: str, psf: np.ndarray, scene: np.ndarray, sensor: np.ndarray,
                       restored: dict[str, np.ndarray]) -> Figure:
    """Scene, PSF (log scale), sensor image, then each restorer's output; the sensor image and each
    output are titled with their own PSNR / SSIM against the scene (``image_scores``)."""
    panels = [("scene (the reference)", scene), (f"PSF {psf.shape[-1]}x{psf.shape[-1]} px (log)", _psf_rgb(psf)),
              (f"sensor\n{_score_text(image_scores(sensor, scene))}", sensor)]
    panels += [(f"{name}\n{_score_text(image_scores(img, scene))}", img) for name, img in restored.items()]
    cols = min(4, len(panels))
    rows = math.ceil(len(panels) / cols)
    aspect = scene.shape[0] / scene.shape[1]
    note_in = 0.45
    height = _CELL_IN * aspect * rows + 0.8 * rows + 0.5 + note_in
    fig = new_figure(figsize=(_CELL_IN * cols, height))
    axes = fig.subplots(rows, cols, squeeze=False)
    for ax in axes.flat:
        ax.axis("off")
    for ax, (title, img) in zip(axes.flat, panels):
        ax.imshow(np.clip(img, 0, 1), interpolation="nearest" if "PSF" in title else "antialiased")
        ax.set_title(title, fontsize=FONT_PT)
    fig.suptitle(f"lens: {lens_name}", fontsize=FONT_PT + 2)
    fig.text(0.01, 0.1 / height, "\n".join(textwrap.wrap(
        "Under each image: that image's own PSNR and SSIM against the scene (the first image of the run). "
        "The run's means over all its images, with 95 % intervals, are in table.md.",
        int((_CELL_IN * cols - 0.2) * 72 / (0.56 * NOTE_PT)))),
        fontsize=NOTE_PT, color="0.25", ha="left", va="bottom")
    fig.tight_layout(rect=(0, note_in / height, 1, 1))
    return fig


def write_sample_grid(path: Path, lens_name: str, psf: np.ndarray, scene: np.ndarray, sensor: np.ndarray,
                      restored: dict[str, np.ndarray]) -> Path:
    """One PNG of ``sample_grid_figure``. ``psf`` is (3, K, K); ``scene``, ``sensor`` and each ``restored``
    image are (H, W, 3) in [0, 1]. Returns ``path``."""
    return save_figure(sample_grid_figure(lens_name, psf, scene, sensor, restored), path, dpi=DPI, layout=False)
