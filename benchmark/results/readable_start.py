"""Where readable plates start: the smallest width bin in which the strongest reader reads at least
half of the sharp plates.

The pooled plate accuracy of every row counts the plates from that width
(``benchmark.results.plate_scoring.READABLE_MIN_WIDTH_PX``); below it no attacker reads a plate even
without a lens, so a lens earns no privacy there. The width is measured, not chosen: the readers of
the standard ensemble read the sharp plate windows of the quick profile (seed 0, no lens), per width
bin, and the start is the lower edge of the smallest bin where the best of them reads >= half the
plates. The measurement ships as ``readable_start.json`` beside this module, with its counts and
provenance; ``python -m benchmark.studies.readable_start_study`` re-measures it (after the sharp reader or
the scenes change).
"""

from __future__ import annotations

import json
import warnings
from collections.abc import Mapping, Sequence
from pathlib import Path
from typing import Any

__all__ = ["MEASUREMENT", "READ_SHARE", "measured_start", "start_from"]

MEASUREMENT = Path(__file__).with_name("readable_start.json")
READ_SHARE = 0.5


def start_from(bins: Sequence[Mapping[str, Any]], share: float = READ_SHARE) -> int | None:
    """The lower edge of the smallest bin (``{"low_px", "hits", "n"}``, hits of the best reader) where
    hits / n >= `share`; None when no bin reaches it."""
    for b in sorted(bins, key=lambda b: b["low_px"]):
        if b["n"] and b["hits"] / b["n"] >= share:
            return int(b["low_px"])
    return None


def measured_start(bins_px: Sequence[int], path: Path = MEASUREMENT, missing_px: int = 32) -> int:
    """The shipped start, checked against its own counts and against the scoring's bins `bins_px`.
    Without the file (only while the study that writes it runs for the first time), `missing_px`,
    with a warning.

    Raises:
        RuntimeError: the file is malformed, its start does not follow from its counts, or it is not
            a lower edge of `bins_px`; the message says how to re-measure it.
    """
    remedy = "re-measure it with `python -m benchmark.studies.readable_start_study`"
    if not path.exists():
        warnings.warn(f"no readable-start measurement at {path}: plates are readable from {missing_px} px until "
                      f"it is measured; {remedy}", stacklevel=2)
        return missing_px
    try:
        record = json.loads(path.read_text())
        start, bins = int(record["start_px"]), record["bins"]
    except (OSError, ValueError, KeyError, TypeError) as exc:
        raise RuntimeError(f"the readable-start measurement {path} cannot be read ({exc}); {remedy}") from exc
    if start_from(bins) != start:
        raise RuntimeError(f"{path} says plates are readable from {start} px, but its counts give "
                           f"{start_from(bins)} px; {remedy}")
    if start not in bins_px:
        raise RuntimeError(f"{path} starts readable plates at {start} px, not a width bin of {tuple(bins_px)}; {remedy}")
    return start
