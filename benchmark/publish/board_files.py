"""The leaderboard's files beyond its README: what `report` writes and what it deletes.

Everything under ``leaderboard/`` is either an entry (``entries/*.json``), a study (``studies/``), or
written by ``python -m benchmark report`` from them: README.md (short: the headline table, the findings
and links), attackers.md (every attacker's figures and each chain's part in its lens's ensemble),
charts.md (every chart and sample picture), index.html, ``charts/*.png`` and the published runs'
``samples/*.png``. ``prune`` deletes what no entry or study backs: a chart this render did not write
(e.g. of a study or a chart kind that no longer exists) and a sample picture of a lens and profile
that has no entry. Plate accuracy against width is drawn per entry from the entry's per-plate
outcomes (``plate_width__{entry}.png``, where its plate units record each plate's width), not copied
from the run that published it, so there is one chart per lens and profile whatever the number of
runs that published it.
"""

from __future__ import annotations

import logging
from collections.abc import Iterable, Sequence
from pathlib import Path

from benchmark.publish.tables import attacker_table, contributions_table
from benchmark.results.charts.plate_width import write_plate_width_chart
from benchmark.results.ensemble import READER_KINDS, WIDTH_VALUE
from benchmark.results.entries import Entry, entry_name, file_safe
from benchmark.store.cache import atomic_write_text

log = logging.getLogger(__name__)

ATTACKERS_PAGE = "attackers.md"
CHARTS_PAGE = "charts.md"
# The folders whose files `report` owns (and prunes); entries/ and studies/ are its inputs.
RENDERED_DIRS = ("charts", "samples")
PLATE_WIDTH_PREFIX = "plate_width__"


def entry_stem(entry: Entry) -> str:
    return entry_name(entry.lens, entry.profile, entry.scenes).removesuffix(".json")


def plate_records(entry: Entry) -> list[dict]:
    """The entry's per-plate outcomes of its reader chains as plates.csv records (lens, attack, width_px,
    correct), for the rows whose plate units record each plate's width."""
    records = []
    for row in entry.rows:
        units = row.units
        if not (row.ok and row.kind in READER_KINDS and units is not None and units.unit == "plate"
                and WIDTH_VALUE in units.values and "correct" in units.values):
            continue
        records += [{"lens": entry.lens, "attack": row.attack, "width_px": float(w), "correct": bool(c)}
                    for w, c in zip(units.values[WIDTH_VALUE], units.values["correct"])]
    return records


def plate_width_charts(entries: Sequence[Entry], charts: Path) -> list[Path]:
    """One plate-accuracy-against-width chart per entry whose plates record their widths."""
    written = []
    for entry in entries:
        records = plate_records(entry)
        if records:
            written.append(write_plate_width_chart(records, charts / f"{PLATE_WIDTH_PREFIX}{entry_stem(entry)}.png"))
    return written


def backed_samples(entries: Sequence[Entry], samples: Path) -> list[Path]:
    """The published pictures in `samples` that belong to an entry: `{lens}__{profile}.png` and
    `{lens}__{profile}__curves.png` (publish.leaderboard.copy_run_pictures) of an entry's lens and profile."""
    if not samples.is_dir():
        return []
    names = {f"{file_safe(e.lens)}__{file_safe(e.profile)}{suffix}.png" for e in entries for suffix in ("", "__curves")}
    return sorted(p for p in samples.glob("*.png") if p.name in names)


def prune(directory: Path, keep: Iterable[Path]) -> list[Path]:
    """Delete every file under `directory`'s RENDERED_DIRS that is not in `keep`; returns what was deleted."""
    kept = {Path(p).resolve() for p in keep}
    removed = []
    for name in RENDERED_DIRS:
        folder = directory / name
        if not folder.is_dir():
            continue
        for path in sorted(folder.rglob("*")):
            if (path.is_file() or path.is_symlink()) and path.resolve() not in kept:
                path.unlink()
                removed.append(path)
                log.info("deleted %s: no entry or study backs it", path)
    return removed


def attackers_text(entries: Sequence[Entry]) -> str:
    """attackers.md: each chain's part in its lens's plate ensemble, then every attacker's own figures."""
    return "\n".join([
        "# Every attacker", "",
        "Rendered by `python -m benchmark report` from `leaderboard/entries/*.json`; never edited by hand. "
        "Back to the [leaderboard](README.md).", "",
        "## The ensemble's chains", "",
        "Each chain's part in its lens's plate ensemble, pooled over seeds (chains that read no plate left out). "
        "Which chains decide a plate or a scene, and what removing each would cost: "
        "[docs/ensemble.md](../docs/ensemble.md).", "",
        contributions_table(entries), "",
        "## Every attacker", "",
        "Every attack chain of every entry with its own figures: mean ± standard deviation over the seeds listed.", "",
        attacker_table(entries), ""])


def charts_text(charts: Sequence[Path], widths: Sequence[Path], pictures: Sequence[Path]) -> str:
    """charts.md: the leaderboard's charts, plate accuracy against width (one per entry), the sample pictures."""
    text = ["# Charts and samples", "",
            "Rendered by `python -m benchmark report`; never edited by hand. Back to the [leaderboard](README.md).",
            "", "## Charts", ""]
    text += [f"![{p.stem}](charts/{p.name})" for p in charts]
    text += ["", "## Plate accuracy against plate width (one chart per entry)", ""]
    text += ([f"![{p.stem}](charts/{p.name})" for p in widths] or
             ["None: no entry records its plates' widths yet (entries published before per-plate widths were "
              "stored); the next re-publish adds one chart per entry."])
    samples = [p for p in pictures if not p.name.endswith("__curves.png")]
    curves = [p for p in pictures if p.name.endswith("__curves.png")]
    if samples:
        text += ["", "## Sample images (each entry's first seed, from the run that published it)", ""]
        text += [f"![{p.stem}](samples/{p.name})" for p in samples]
    if curves:
        text += ["", "## Co-design training curves (first seed)", ""]
        text += [f"![{p.stem}](samples/{p.name})" for p in curves]
    return "\n".join(text) + "\n"


def write_pages(directory: Path, entries: Sequence[Entry], charts: Sequence[Path], widths: Sequence[Path],
                pictures: Sequence[Path]) -> list[Path]:
    """Write attackers.md and charts.md into `directory`; returns their paths."""
    attackers, charts_page = directory / ATTACKERS_PAGE, directory / CHARTS_PAGE
    atomic_write_text(attackers, attackers_text(entries))
    atomic_write_text(charts_page, charts_text(charts, widths, pictures))
    return [attackers, charts_page]
