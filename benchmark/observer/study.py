"""The ideal-observer study: the ceiling curve and W_5% of every lens of the quick leaderboard.

For each lens (built from its entry's `lens_spec`, the co-designed coefficients included, never
retrained): plate and per-character ceilings at every width of `WIDTHS_PX` for T = 1 and 30 frames,
the certified widths W_5%, and the seconds it took. For `DEPTH_LENSES` the same curve once more with
the PSF at each width's own object distance (`lenses.depth.plate_distance_m`), to show whether one
object plane suffices. Each lens's record keeps the lens spec it was computed for (`lens_spec`), so
the leaderboard shows a ceiling only beside an entry of that very lens (benchmark.observer.published).
Writes leaderboard/studies/ideal_observer.json and its chart leaderboard/charts/ideal_observer.png
(benchmark.charts.ideal_observer, re-rendered by `python -m benchmark report` with the readers on it).
"""

from __future__ import annotations

import json
import logging
import time
from pathlib import Path

from benchmark.observer.ceiling import CeilingCurve, PlateModel, Precision, ceiling_curves, certified_width
from lenses import Lens, parse_spec

WIDTHS_PX = (4, 6, 8, 12, 16, 24, 32, 48, 64, 96, 128, 160)
FRAMES = (1, 30)
DEPTH_LENSES = ("ideal", "defocus", "os-d-1000", "gp")
EPS = 0.05
REPO = Path(__file__).resolve().parents[2]

log = logging.getLogger(__name__)


def quick_lens_specs(entries_dir: Path = REPO / "leaderboard" / "entries") -> dict[str, dict]:
    """The stored lens spec of every lens of the quick synthetic leaderboard (name -> spec dict)."""
    found = {}
    for path in sorted(entries_dir.glob("*__quick__synthetic.json")):
        entry = json.loads(path.read_text(encoding="utf-8"))
        if entry.get("lens_spec") is not None:  # the `sharp` reference has no lens
            found[entry["lens"]] = entry["lens_spec"]
    if not found:
        raise FileNotFoundError(f"no quick leaderboard entry with a lens_spec under {entries_dir}")
    return found


def quick_lenses(entries_dir: Path = REPO / "leaderboard" / "entries") -> dict[str, Lens]:
    """Every lens of the quick synthetic leaderboard, from its entry's stored spec (name -> Lens)."""
    return {name: Lens(parse_spec(spec, source=f"{entries_dir}/{name}__quick__synthetic.json"))
            for name, spec in quick_lens_specs(entries_dir).items()}


def summary(curve: CeilingCurve) -> dict:
    """W_5% (plate, per character), the ceilings at 32 px and the whole curve, JSON-ready."""
    at32 = list(curve.widths_px).index(32) if 32 in curve.widths_px else None
    return {"w5_plate_px": certified_width(curve, EPS), "w5_char_px": certified_width(curve, EPS, per_character=True),
            "plate_ceiling_w32": None if at32 is None else float(curve.plate_ceiling[at32]),
            "char_ceiling_w32": None if at32 is None else float(curve.char_ceiling[at32]),
            "curve": curve.to_dict()}


def run_study(out_json: Path = REPO / "leaderboard" / "studies" / "ideal_observer.json",
              out_png: Path = REPO / "leaderboard" / "charts" / "ideal_observer.png",
              names: tuple[str, ...] | None = None, widths_px: tuple[int, ...] = WIDTHS_PX,
              frames: tuple[int, ...] = FRAMES, depth_lenses: tuple[str, ...] = DEPTH_LENSES, seed: int = 0,
              precision: Precision = Precision(max_plates=40)) -> dict:
    """Compute the study (module docstring) for `names` (default: all quick lenses); write json + png."""
    specs = quick_lens_specs()
    lenses_by_name = quick_lenses()
    names = names or tuple(lenses_by_name)
    record: dict = {"eps": EPS, "widths_px": list(widths_px), "frames": list(frames), "seed": seed,
                    "plate_model": PlateModel().__dict__, "precision": precision.__dict__, "lenses": {}}
    for name in names:
        lens = lenses_by_name[name]
        t0 = time.perf_counter()
        curves = ceiling_curves(lens, widths_px, frames, seed=seed, precision=precision)
        # The spec travels with the curve: the leaderboard shows it only for entries of the same lens.
        entry = {"lens_spec": specs[name], "seconds": time.perf_counter() - t0,
                 **{f"t{c.frames}": summary(c) for c in curves}}
        if name in depth_lenses:
            t0 = time.perf_counter()
            deep = ceiling_curves(lens, widths_px, frames, seed=seed, precision=precision, at_own_distance=True)
            entry["at_own_distance"] = {"seconds": time.perf_counter() - t0,
                                        **{f"t{c.frames}": summary(c) for c in deep}}
        record["lenses"][name] = entry
        log.info("%s: %.0f s, W5 plate T=1 %s px", name, entry["seconds"], entry["t1"]["w5_plate_px"])
        out_json.parent.mkdir(parents=True, exist_ok=True)
        out_json.write_text(json.dumps(record, indent=1) + "\n", encoding="utf-8")  # after each lens: resumable by eye
    write_chart(record, out_png)
    return record


def write_chart(record: dict, path: Path) -> Path:
    """The study's chart (benchmark.charts.ideal_observer) with the published entries' readers on it."""
    from benchmark.charts.ideal_observer import write_ideal_observer_chart
    from benchmark.leaderboard_entries import load_entries
    return write_ideal_observer_chart(record, load_entries(path.parent.parent), path)
