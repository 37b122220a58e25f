"""The ideal-observer study: the ceiling curve and W_5% of every lens of the quick leaderboard.

For each lens (built from its entry's `lens_spec`, the co-designed coefficients included, never
retrained): plate and per-character ceilings at every width of `WIDTHS_PX` for T = 1 and 30 frames,
the certified widths W_5%, and the seconds it took. For `DEPTH_LENSES` the same curve once more with
the PSF at each width's own object distance (`lenses.depth.plate_distance_m`), to show whether one
object plane suffices. Writes leaderboard/studies/ideal_observer.json and its chart
leaderboard/charts/ideal_observer.png.
"""

from __future__ import annotations

import json
import time
from pathlib import Path

import matplotlib.pyplot as plt
import numpy as np

from benchmark.charts import save_figure
from benchmark.observer.ceiling import CeilingCurve, PlateModel, Precision, ceiling_curves, certified_width
from lenses import Lens, parse_spec

WIDTHS_PX = (4, 6, 8, 12, 16, 24, 32, 48, 64, 96, 128, 160)
FRAMES = (1, 30)
DEPTH_LENSES = ("ideal", "defocus", "os-d-1000", "gp")
EPS = 0.05
REPO = Path(__file__).resolve().parents[2]


def quick_lenses(entries_dir: Path = REPO / "leaderboard" / "entries") -> dict[str, Lens]:
    """Every lens of the quick synthetic leaderboard, from its entry's stored spec (name -> Lens)."""
    found = {}
    for path in sorted(entries_dir.glob("*__quick__synthetic.json")):
        entry = json.loads(path.read_text(encoding="utf-8"))
        spec = entry.get("lens_spec")
        if spec is None:  # the `sharp` reference has no lens
            continue
        found[entry["lens"]] = Lens(parse_spec(spec, source=str(path)))
    if not found:
        raise FileNotFoundError(f"no quick leaderboard entry with a lens_spec under {entries_dir}")
    return found


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
    lenses_by_name = quick_lenses()
    names = names or tuple(lenses_by_name)
    record: dict = {"eps": EPS, "widths_px": list(widths_px), "frames": list(frames), "seed": seed,
                    "plate_model": PlateModel().__dict__, "precision": precision.__dict__, "lenses": {}}
    for name in names:
        lens = lenses_by_name[name]
        t0 = time.perf_counter()
        curves = ceiling_curves(lens, widths_px, frames, seed=seed, precision=precision)
        entry = {"seconds": time.perf_counter() - t0, **{f"t{c.frames}": summary(c) for c in curves}}
        if name in depth_lenses:
            t0 = time.perf_counter()
            deep = ceiling_curves(lens, widths_px, frames, seed=seed, precision=precision, at_own_distance=True)
            entry["at_own_distance"] = {"seconds": time.perf_counter() - t0,
                                        **{f"t{c.frames}": summary(c) for c in deep}}
        record["lenses"][name] = entry
        print(f"{name}: {entry['seconds']:.0f} s, W5 plate T=1 {entry['t1']['w5_plate_px']} px", flush=True)
        out_json.parent.mkdir(parents=True, exist_ok=True)
        out_json.write_text(json.dumps(record, indent=1) + "\n", encoding="utf-8")  # after each lens: resumable by eye
    write_chart(record, out_png)
    return record


def write_chart(record: dict, path: Path) -> Path:
    """Plate ceiling vs width per lens: T = 1 solid, T = 30 dashed, own-distance PSF dotted, 5 % line."""
    fig, axes = plt.subplots(1, 2, figsize=(12, 4.8), sharey=True)
    colours = plt.rcParams["axes.prop_cycle"].by_key()["color"]
    for ax, key, title in zip(axes, ("plate", "char"), ("whole plate (least block: characters, letter pair)", "per character (mean)")):
        for n, (name, entry) in enumerate(record["lenses"].items()):
            colour = colours[n % len(colours)]
            for frames, style in (("t1", "-"), ("t30", "--")):
                if frames not in entry:
                    continue
                curve = entry[frames]["curve"]
                ax.plot(curve["widths_px"], np.asarray(curve[f"{key}_ceiling"]) * 100, style, color=colour,
                        label=name if frames == "t1" else None)
            deep = entry.get("at_own_distance", {}).get("t1")
            if deep:
                ax.plot(deep["curve"]["widths_px"], np.asarray(deep["curve"][f"{key}_ceiling"]) * 100, ":",
                        color=colour)
        ax.axhline(100 * record["eps"], color="k", lw=0.8)
        ax.set_xscale("log")
        ax.set_xlabel("plate width (px)")
        ax.set_title(f"Ideal-observer ceiling, {title}")
    axes[0].set_ylabel("ceiling on correct reads (%)")
    axes[0].legend(fontsize=7, ncol=2, title="solid T=1, dashed T=30, dotted PSF at own distance (T=1)",
                   title_fontsize=7)
    return save_figure(fig, path)
