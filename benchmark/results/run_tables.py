"""A run's tables: table.csv (every row) and table.md (the seed summary by row kind), from typed rows."""

from __future__ import annotations

import math
from collections.abc import Sequence
from pathlib import Path

import pandas as pd

from benchmark.store.cache import atomic_write_text
from benchmark.results.schema import Row

ID_COLUMNS = ["lens", "attack", "profile", "scenes"]
# table.md is split by row kind, each section with the columns that kind has; a section keeps
# only rows that have its first measured column (e.g. a reader on scenes without a readable plate).
SECTIONS = (
    ("Utility (segmentation of the sensor image)", ("utility",),
     ["miou", "mean_acc", "overall_acc", "fit_s", "images_per_s"]),
    ("Restorers (deblurring attacks)", ("restorer",), ["threat_model", "psnr_db", "ssim", "fit_s", "images_per_s"]),
    ("Plate readers (on the sensor image and after each restorer)", ("reader", "chain"),
     ["threat_model", "plate_acc", "plate_cer", "plate_det", "n_plates", "images_per_s"]),
    ("References", ("reference",), ["threat_model", "psnr_db", "ssim", "plate_acc", "images_per_s"]),
    ("Attack-independent bound", ("bound",),
     ["bound_bits_w32_t1", "bound_ceiling_w32_t1", "bound_width_eps_t1", "fit_s"]),
    ("Lenses", ("lens",), ["psf_size_px", "psf_energy", "fit_s", "images_per_s"]),
)


def write_plate_records(out: Path, records: list[dict]) -> Path:
    """plates.csv: one line per (lens, chain, seed, readable plate): truth, width, read, correct, cer."""
    path = Path(out) / "plates.csv"
    atomic_write_text(path, pd.DataFrame(records).to_csv(index=False))
    return path


def summary_table(rows: Sequence[Row]) -> pd.DataFrame:
    """One line per (lens, attack, profile, scenes) of the rows that succeeded: the kind, seeds,
    threat model, metric means and, with several seeds, stds (``NAME_std``)."""
    df = pd.DataFrame([r.flat() for r in rows if r.ok])
    metrics = sorted({name for r in rows if r.ok for name in r.metrics})
    group = df.groupby(ID_COLUMNS, sort=False)
    table = group[metrics].mean()
    seeds = group["seed"].nunique()
    if int(seeds.max()) > 1:
        table = table.join(group[metrics].std(ddof=1).add_suffix("_std"))
    table.insert(0, "threat_model", group["threat_model"].first())
    table.insert(0, "seeds", seeds)
    table.insert(0, "kind", group["kind"].first())
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


def failures_markdown(rows: Sequence[Row]) -> str:
    """The failed rows (attacker, stage, message), or "" when every row succeeded."""
    failed = [r for r in rows if not r.ok and r.error is not None]
    if not failed:
        return ""
    lines = ["| lens | attack | seed | attacker | stage | error |", "|---|---|---|---|---|---|"]
    lines += [f"| {r.lens} | {r.attack} | {r.seed} | {r.error.attacker} | {r.error.stage} | "
              f"{r.error.message.replace('|', '/').splitlines()[0] if r.error.message else ''} |" for r in failed]
    return "\n".join(lines)


def sectioned_markdown(rows: Sequence[Row]) -> str:
    """table.md: one section per row kind (SECTIONS), then the failed attackers."""
    table = summary_table(rows) if any(r.ok for r in rows) else pd.DataFrame(columns=["kind"])
    parts = []
    for title, kinds, columns in SECTIONS:
        section = table[table["kind"].isin(kinds)]
        measured = [c for c in columns if c != "threat_model"]
        section = section[section[measured[0]].notna()] if measured[0] in section else section.iloc[0:0]
        if section.empty:
            continue
        keep = ["lens", "attack", "seeds"] + [c for c in columns if c in section.columns]
        keep += [f"{c}_std" for c in columns if f"{c}_std" in section.columns]
        parts += [f"### {title}", "", markdown_table(section[keep].dropna(axis=1, how="all")), ""]
    failures = failures_markdown(rows)
    if failures:
        parts += ["### Failed attackers (no metric; see results.json)", "", failures, ""]
    profile, scenes = rows[0].profile, rows[0].scenes
    return f"Profile `{profile}`, scenes `{scenes}`; mean ± std over seeds.\n\n" + "\n".join(parts)


def write_tables(out: Path, rows: Sequence[Row]) -> pd.DataFrame:
    """table.csv (every row flat, full precision, failed rows included) and table.md (the seed
    summary by row kind, rounded). Returns the summary."""
    out = Path(out)
    atomic_write_text(out / "table.csv", pd.DataFrame([r.flat() for r in rows]).to_csv(index=False))
    atomic_write_text(out / "table.md", sectioned_markdown(rows))
    return summary_table(rows) if any(r.ok for r in rows) else pd.DataFrame()
