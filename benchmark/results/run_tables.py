"""A run's tables: table.csv (every row) and table.md (the seed summary by row kind), from typed rows."""

from __future__ import annotations

import math
from collections.abc import Sequence
from pathlib import Path

import pandas as pd

from benchmark.store.cache import atomic_write_text
from benchmark.results.markdown import md_cell, md_code
from benchmark.results.schema import Row, threat_models

ID_COLUMNS = ["lens", "attack", "profile", "scenes"]
CI_LOW, CI_HIGH = "_ci_low", "_ci_high"  # the 95 % interval's columns beside a metric's (as benchmark.api's)
# table.md is split by row kind, each section with the columns that kind has; a section keeps only
# rows that have one of its needed columns (the last element: e.g. not a reader on scenes without a
# readable plate), so a reference read by each reader (raw>lpdr) is a References line, as charts show it.
SECTIONS = (
    ("Utility (segmentation of the sensor image)", ("utility",),
     ["miou", "mean_acc", "overall_acc", "fit_s", "images_per_s"], ("miou",)),
    ("Restorers (deblurring attacks)", ("restorer",), ["threat_model", "psnr_db", "ssim", "fit_s", "images_per_s"],
     ("psnr_db",)),
    ("Plate readers (on the sensor image and after each restorer)", ("reader", "chain"),
     ["threat_model", "plate_acc", "plate_cer", "plate_det", "n_plates", "fit_s", "images_per_s"], ("plate_acc",)),
    ("References", ("reference",), ["threat_model", "psnr_db", "ssim", "plate_acc", "images_per_s"],
     ("psnr_db", "plate_acc")),
    ("Attack-independent bound", ("bound",),
     ["bound_bits_w32_t1", "bound_ceiling_w32_t1", "bound_width_eps_t1", "fit_s"], ("bound_bits_w32_t1",)),
    ("Lenses", ("lens",), ["psf_size_px", "psf_energy", "fit_s", "images_per_s"], ("psf_size_px",)),
)


def write_plate_records(out: Path, records: list[dict]) -> Path:
    """plates.csv: one line per (lens, chain, seed, readable plate): truth, width, read, correct, cer."""
    path = Path(out) / "plates.csv"
    atomic_write_text(path, pd.DataFrame(records).to_csv(index=False))
    return path


def flat_rows(rows: Sequence[Row]) -> pd.DataFrame:
    """Every row flat (`Row.flat`), each metric with a 95 % interval followed by ``NAME_ci_low`` and
    ``NAME_ci_high`` (the row's own interval; empty where a row has none), and each chain's threat
    model the strongest of its parts (`schema.threat_models`)."""
    threat = threat_models(rows)
    with_interval = {name for r in rows for name in r.intervals}
    records = []
    for r in rows:
        flat = r.flat()
        flat["threat_model"] = threat.get(r.attack, r.threat_model) if r.ok else r.threat_model
        record: dict[str, object] = {}
        for key, value in flat.items():
            record[key] = value
            if key in with_interval and key in r.metrics:
                record[key + CI_LOW], record[key + CI_HIGH] = r.intervals.get(key, (math.nan, math.nan))
        records.append(record)
    columns = list(dict.fromkeys(k for rec in records for k in rec))
    for name in with_interval:  # a metric some rows have without an interval: its columns all the same
        for suffix in (CI_LOW, CI_HIGH):
            if name + suffix not in columns:
                columns.insert(columns.index(name) + (1 if suffix == CI_LOW else 2), name + suffix)
    return pd.DataFrame.from_records(records, columns=columns)


def summary_table(rows: Sequence[Row]) -> pd.DataFrame:
    """One line per (lens, attack, profile, scenes) of the rows that succeeded: the kind, seeds,
    threat model (a chain's: the strongest of its parts), metric means, their 95 % interval over the
    seeds (``NAME_ci_low``: the lowest seed's lower limit, ``NAME_ci_high``: the highest seed's upper
    limit; one seed's own interval) and, with several seeds, stds (``NAME_std``)."""
    ok = [r for r in rows if r.ok]
    df = flat_rows(ok)
    metrics = sorted({name for r in ok for name in r.metrics})
    group = df.groupby(ID_COLUMNS, sort=False)
    table = group[metrics].mean()
    lows = [m + CI_LOW for m in metrics if m + CI_LOW in df.columns]
    highs = [m + CI_HIGH for m in metrics if m + CI_HIGH in df.columns]
    table = table.join(group[lows].min()).join(group[highs].max())
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


def _is_extra(col: str) -> bool:
    return col.endswith(("_std", CI_LOW, CI_HIGH))


def markdown_table(table: pd.DataFrame) -> str:
    """The summary as markdown: a metric and its 95 % interval in one cell ("mean [low, high]"), and
    with several seeds its seed standard deviation in a column of its own ("NAME seed sd"; timings,
    which have no interval, show the mean only)."""
    shown = pd.DataFrame(index=table.index)
    for col in [c for c in table.columns if not _is_extra(c)]:
        cells = []
        for i, v in enumerate(table[col]):
            text = _fmt(v)
            if text and col + CI_LOW in table.columns and not pd.isna(table[col + CI_LOW].iloc[i]):
                text += f" [{_fmt(float(table[col + CI_LOW].iloc[i]))}, {_fmt(float(table[col + CI_HIGH].iloc[i]))}]"
            cells.append(md_cell(text))  # lens and attacker names are plugins' text
        shown[col] = cells
        if f"{col}_std" in table.columns and col + CI_LOW in table.columns:  # timings: the mean only
            shown[f"{col} seed sd"] = [_fmt(float(v)) for v in table[f"{col}_std"]]
    return shown.to_markdown(index=False)


def failures_markdown(rows: Sequence[Row]) -> str:
    """The failed rows (attacker, stage, message), or "" when every row succeeded."""
    failed = [r for r in rows if not r.ok and r.error is not None]
    if not failed:
        return ""
    lines = ["| lens | attack | seed | attacker | stage | error |", "|---|---|---|---|---|---|"]
    lines += ["| " + " | ".join(md_cell(c) for c in (r.lens, r.attack, r.seed, r.error.attacker, r.error.stage,
                                                     r.error.message.splitlines()[0] if r.error.message else ""))
              + " |" for r in failed]
    return "\n".join(lines)


def ensemble_markdown(rows: Sequence[Row]) -> str:
    """Per lens, the ensemble's plate accuracy and PSNR (benchmark.results.ensemble) beside the strongest
    single chain's, each with its 95 % interval; "" when no row carries per-unit outcomes."""
    from benchmark.results.ensemble import plate_ensemble, scene_ensemble, strongest_chain
    lines = []
    for lens in dict.fromkeys(r.lens for r in rows):
        mine = [r for r in rows if r.lens == lens]
        plates, scenes = plate_ensemble(mine), scene_ensemble(mine)
        if plates is None and scenes is None:
            continue
        single = None if plates is None else strongest_chain(plates)
        lines.append([lens, "" if plates is None else f"{plates.accuracy.text()} ({len(plates.chains)} chains)",
                      "" if single is None else f"{single[1].text()} ({single[0]})",
                      "" if scenes is None else f"{scenes.text()} ({len(scenes.restorers)} restorers)"])
    if not lines:
        return ""
    head = ["lens", "ensemble plate acc % [95 %]", "strongest single chain plate acc % [95 %]",
            "ensemble PSNR dB [95 %]"]
    return "\n".join(["| " + " | ".join(head) + " |", "|" + "|".join(["---"] * len(head)) + "|"]
                     + ["| " + " | ".join(md_cell(c) for c in line) + " |" for line in lines])


def sectioned_markdown(rows: Sequence[Row]) -> str:
    """table.md: one section per row kind (SECTIONS), then the failed attackers."""
    table = summary_table(rows) if any(r.ok for r in rows) else pd.DataFrame(columns=["kind"])
    parts = []
    for title, kinds, columns, needed in SECTIONS:
        section = table[table["kind"].isin(kinds)]
        present = [c for c in needed if c in section]
        section = section[section[present].notna().any(axis=1)] if present else section.iloc[0:0]
        if section.empty:
            continue
        keep = ["lens", "attack", "seeds"] + [c for c in columns if c in section.columns]
        keep += [f"{c}{x}" for c in columns for x in (CI_LOW, CI_HIGH, "_std") if f"{c}{x}" in section.columns]
        parts += [f"### {title}", "", markdown_table(section[keep].dropna(axis=1, how="all")), ""]
    ensemble = ensemble_markdown(rows)
    if ensemble:
        parts += ["### Ensemble: every attacker at once (a plate read by any chain, a scene at its best restorer)", "",
                  ensemble, ""]
    failures = failures_markdown(rows)
    if failures:
        parts += ["### Failed attackers (no metric; see results.json)", "", failures, ""]
    profile, scenes = rows[0].profile, rows[0].scenes
    return (f"Profile {md_code(profile)}, scenes {md_code(scenes)}; each metric as mean over seeds [95 % interval: from the "
            "lowest seed's lower limit to the highest seed's upper limit]; with several seeds, the seed standard "
            "deviation in its own column. A chain's threat model is the strongest of its parts.\n\n"
            + "\n".join(parts))


def write_tables(out: Path, rows: Sequence[Row]) -> pd.DataFrame:
    """table.csv (every row flat, full precision, failed rows included) and table.md (the seed
    summary by row kind, rounded). Returns the summary."""
    out = Path(out)
    atomic_write_text(out / "table.csv", flat_rows(rows).to_csv(index=False))
    atomic_write_text(out / "table.md", sectioned_markdown(rows))
    return summary_table(rows) if any(r.ok for r in rows) else pd.DataFrame()
