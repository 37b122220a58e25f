"""The charts of one run, written next to its results.json."""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from pathlib import Path

import numpy as np

from benchmark.results.charts.bound_chart import write_bound_chart
from benchmark.results.charts.plate_width import write_plate_width_chart
from benchmark.results.charts.restorers import restorer_points, write_restorer_speed_chart
from benchmark.results.schema import Row


def write_run_charts(out: Path, rows: Sequence[Row], plates: list[dict],
                     bound_curves: Mapping[str, tuple[np.ndarray, np.ndarray]]) -> list[Path]:
    """Restorer speed vs PSNR, plate accuracy vs width (with the bound's ceiling) and the bound's
    ceiling vs width, each where the run has the data. Returns the written paths."""
    written = []
    if restorer_points(rows):
        written.append(write_restorer_speed_chart(rows, out / "restorers_speed_vs_psnr.png"))
    if plates:
        written.append(write_plate_width_chart(plates, out / "plate_accuracy_vs_width.png", ceilings=bound_curves))
    if bound_curves:
        written.append(write_bound_chart(dict(bound_curves), out / "bound_ceiling_vs_width.png"))
    return written
