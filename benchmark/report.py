"""Run outputs: results.json, table.md, table.csv and the sample-image grid per lens."""

from __future__ import annotations

import json
import math
from pathlib import Path

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402
import pandas as pd  # noqa: E402

from benchmark.cache import atomic_write_text  # noqa: E402
from benchmark.charts import save_figure  # noqa: E402

SCHEMA_VERSION = 1
ID_COLUMNS = ["lens", "attack", "profile", "scenes"]
METRIC_COLUMNS = ["threat_model", "miou", "mean_acc", "overall_acc", "psnr_db", "ssim", "plate_acc", "plate_cer",
                  "plate_det", "n_plates", "bound_bits_w32_t1", "bound_ceiling_w32_t1", "bound_width_eps_t1",
                  "psf_size_px", "psf_energy", "fit_s", "images_per_s"]


def write_results(out: Path, rows: list[dict], meta: dict) -> Path:
    """results.json: {"schema_version", "meta" (profile values, command), "rows": [flat rows]}."""
    path = Path(out) / "results.json"
    atomic_write_text(path, json.dumps({"schema_version": SCHEMA_VERSION, "meta": meta, "rows": rows},
                                       indent=1, default=str, allow_nan=True))
    return path


def write_plate_records(out: Path, records: list[dict]) -> Path:
    """plates.csv: one line per (lens, chain, seed, readable plate): truth, width, read, correct, cer."""
    path = Path(out) / "plates.csv"
    atomic_write_text(path, pd.DataFrame(records).to_csv(index=False))
    return path


def summary_table(rows: list[dict]) -> pd.DataFrame:
    """One line per (lens, attack, profile, scenes): metric means and, with several seeds, stds."""
    df = pd.DataFrame(rows)
    metrics = [c for c in METRIC_COLUMNS if c in df.columns and c != "threat_model"]
    group = df.groupby(ID_COLUMNS, sort=False)
    table = group[metrics].mean()
    seeds = group["seed"].nunique()
    if int(seeds.max()) > 1:
        table = table.join(group[metrics].std(ddof=1).add_suffix("_std"))
    if "threat_model" in df.columns:
        table.insert(0, "threat_model", group["threat_model"].first())
    table.insert(0, "seeds", seeds)
    return table.reset_index().dropna(axis=1, how="all")


def _fmt(v: object) -> str:
    if isinstance(v, float):
        if math.isnan(v):
            return ""
        return f"{v:.3f}" if abs(v) < 100 else f"{v:.1f}"
    return "" if v is None else str(v)


def markdown_table(table: pd.DataFrame) -> str:
    """The summary as markdown, a metric and its seed std in one cell ("mean ± std")."""
    shown = table[[c for c in table.columns if not c.endswith("_std")]].copy().astype(object)
    for col in shown.columns:
        std_col = f"{col}_std"
        cells = []
        for i, v in enumerate(table[col]):
            text = _fmt(v)
            if std_col in table.columns and text and not math.isnan(table[std_col].iloc[i]):
                text += f" ± {_fmt(float(table[std_col].iloc[i]))}"
            cells.append(text)
        shown[col] = cells
    return shown.to_markdown(index=False)


# table.md is split by row kind, each with the columns that kind has.
SECTIONS = (
    ("Utility (segmentation of the sensor image)", lambda a: a == "utility",
     ["miou", "mean_acc", "overall_acc", "fit_s", "images_per_s"]),
    ("Restorers (deblurring attacks)", lambda a: a not in ("lens", "utility", "bound") and ">" not in a,
     ["threat_model", "psnr_db", "ssim", "fit_s", "images_per_s"]),
    ("Plate readers (on the sensor image and after each restorer)", lambda a: True,
     ["threat_model", "plate_acc", "plate_cer", "plate_det", "n_plates", "images_per_s"]),
    ("Attack-independent bound", lambda a: a == "bound",
     ["bound_bits_w32_t1", "bound_ceiling_w32_t1", "bound_width_eps_t1", "fit_s"]),
    ("Lenses", lambda a: a == "lens", ["psf_size_px", "psf_energy", "fit_s", "images_per_s"]),
)


def sectioned_markdown(table: pd.DataFrame) -> str:
    parts = []
    for title, wanted, columns in SECTIONS:
        rows = table[table["attack"].map(wanted)]
        if "plate" in columns[1]:
            rows = rows[rows["plate_acc"].notna()] if "plate_acc" in rows else rows.iloc[0:0]
        elif "psnr_db" in columns:
            rows = rows[rows["psnr_db"].notna()] if "psnr_db" in rows else rows.iloc[0:0]
        if rows.empty:
            continue
        keep = ["lens", "attack", "seeds"] + [c for c in columns if c in rows.columns]
        keep += [f"{c}_std" for c in columns if f"{c}_std" in rows.columns]
        parts += [f"### {title}", "", markdown_table(rows[keep].dropna(axis=1, how="all")), ""]
    profile, scenes = table["profile"].iloc[0], table["scenes"].iloc[0]
    return f"Profile `{profile}`, scenes `{scenes}`; mean ± std over seeds.\n\n" + "\n".join(parts)


def write_tables(out: Path, rows: list[dict]) -> pd.DataFrame:
    """table.csv (every row, full precision) and table.md (the seed summary by row kind, rounded)."""
    out = Path(out)
    atomic_write_text(out / "table.csv", pd.DataFrame(rows).to_csv(index=False))
    table = summary_table(rows)
    atomic_write_text(out / "table.md", sectioned_markdown(table))
    return table


def _psf_rgb(psf: np.ndarray) -> np.ndarray:
    """(3,K,K) PSF -> RGB image, log-scaled over 3 decades so the rings show."""
    p = np.log10(np.maximum(psf / psf.max(), 1e-3)) / 3.0 + 1.0
    return np.clip(p.transpose(1, 2, 0), 0, 1)


def write_sample_grid(path: Path, lens_name: str, psf: np.ndarray, scene: np.ndarray, sensor: np.ndarray,
                      restored: dict[str, np.ndarray], scores: dict[str, str]) -> None:
    """One PNG: scene, PSF (log scale), sensor image, then each restorer's output with its score."""
    panels = [("scene", scene), (f"PSF {psf.shape[-1]}x{psf.shape[-1]} px (log)", _psf_rgb(psf)),
              ("sensor", sensor)]
    panels += [(f"{name}\n{scores.get(name, '')}", img) for name, img in restored.items()]
    cols = min(4, len(panels))
    rows = math.ceil(len(panels) / cols)
    aspect = scene.shape[0] / scene.shape[1]
    fig, axes = plt.subplots(rows, cols, figsize=(4 * cols, 4 * aspect * rows + 0.6 * rows), squeeze=False)
    for ax in axes.flat:
        ax.axis("off")
    for ax, (title, img) in zip(axes.flat, panels):
        ax.imshow(np.clip(img, 0, 1), interpolation="nearest" if "PSF" in title else "antialiased")
        ax.set_title(title, fontsize=9)
    fig.suptitle(f"lens: {lens_name}", fontsize=11)
    save_figure(fig, path, dpi=90)
