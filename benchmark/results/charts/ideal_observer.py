"""The ideal observer's ceiling against plate width, per lens, with the leaderboard's readers on it.

Top: the plate ceiling (left) and the mean per-character ceiling (right) of every lens of the
study, T = 1 solid, T = 30 dashed, the PSF at each width's own distance dotted, the 5 % line.
Bottom: one panel per lens, its T = 1 plate ceiling with the 95 % band and T = 30 dashed, and every
reader and chain of the entries whose lens spec the study matches: the accuracy over all readable
plates with its Wilson 95 % interval (entries keep no per-width accuracy), spread over the shaded
widths it pools (readable plates, 32 px and up); and, as squares at each width bin's centre, the
reader study (leaderboard/studies/ideal_observer_readers.json: `ideal-observer` beside `lpdr-oracle`
on the same plates, per width bin with Wilson 95 % intervals) where its lens spec matches.
"""

from __future__ import annotations

import json
from collections.abc import Sequence
from pathlib import Path

import matplotlib
import matplotlib.ticker
import numpy as np
from matplotlib.figure import Figure

from benchmark.results.charts import new_figure, save_figure
from benchmark.results.entries import Entry


READER_STUDY = Path("studies") / "ideal_observer_readers.json"


def _bin_centre_px(low_px: float, high_px: float | None) -> float:
    """Where a width bin's point is drawn: its geometric centre; an open last bin at 1.25 x its start."""
    return float(np.sqrt(low_px * high_px)) if high_px is not None else 1.25 * low_px


def _reader_study_points(readers: dict | None, name: str, spec: dict | None) -> list[tuple[str, dict]]:
    """(reader, bin) of the reader study for lens `name` when its spec there matches the ceiling's."""
    from benchmark.results.observer.published import same_lens
    if readers is None or not same_lens(readers.get("lens_specs", {}).get(name), spec):
        return []
    return [(reader, b) for reader, record in readers["lenses"].get(name, {}).items() for b in record["bins"]]


def ideal_observer_figure(study: dict, entries: Sequence[Entry] = (), readers: dict | None = None) -> Figure:
    """The chart of the module docstring; `study` is leaderboard/studies/ideal_observer.json, `readers`
    the reader study (ideal_observer_readers.json) or None."""
    from benchmark.results.observer.published import entry_accuracies, study_record
    names = list(study["lenses"])
    fig = new_figure(figsize=(max(12.0, 3.4 * len(names)), 11.0), layout="constrained")
    top, bottom = fig.subfigures(2, 1, height_ratios=(1.0, 1.25))
    colours = [c["color"] for c in matplotlib.rcParams["axes.prop_cycle"]]
    axes = top.subplots(1, 2, sharey=True)
    for ax, key, title in zip(axes, ("plate", "char"), ("whole plate (least block: characters, letter pair)",
                                                       "per character (mean)")):
        for n, (name, record) in enumerate(study["lenses"].items()):
            colour = colours[n % len(colours)]
            for frames, style in (("t1", "-"), ("t30", "--")):
                if frames in record:
                    curve = record[frames]["curve"]
                    ax.plot(curve["widths_px"], 100 * np.asarray(curve[f"{key}_ceiling"], dtype=float), style,
                            color=colour, label=name if frames == "t1" else None)
            deep = record.get("at_own_distance", {}).get("t1")
            if deep:
                ax.plot(deep["curve"]["widths_px"], 100 * np.asarray(deep["curve"][f"{key}_ceiling"], dtype=float),
                        ":", color=colour)
        ax.axhline(100 * study["eps"], color="k", lw=0.8)
        ax.set_xscale("log")
        ax.set_xlabel("plate width (px)")
        ax.set_title(f"Ideal-observer ceiling, {title}", fontsize=10)
    axes[0].set_ylabel("ceiling on correct reads (%)")
    axes[0].legend(fontsize=7, ncol=2, title="solid T=1, dashed T=30, dotted PSF at own distance (T=1)",
                   title_fontsize=7)
    panels = bottom.subplots(1, len(names), sharey=True, squeeze=False)[0]
    for n, (ax, name) in enumerate(zip(panels, names)):
        record = study["lenses"][name]
        curve = record["t1"]["curve"]
        widths = np.asarray(curve["widths_px"], dtype=float)
        band = np.asarray(curve["plate_interval"], dtype=float)
        ax.fill_between(widths, 100 * band[:, 0], 100 * band[:, 1], color="0.8", lw=0)
        ax.plot(widths, 100 * np.asarray(curve["plate_ceiling"], dtype=float), "k-", lw=1.2, label="ceiling T=1")
        if "t30" in record:
            t30 = record["t30"]["curve"]
            ax.plot(t30["widths_px"], 100 * np.asarray(t30["plate_ceiling"], dtype=float), "k--", lw=0.8,
                    label="ceiling T=30")
        points = [(e.profile, m) for e in entries if study_record(study, name, e.lens_spec) is not None
                  and e.lens == name for m in entry_accuracies(e)]
        lo, hi = 32.0, 160.0  # readable plates (>= 32 px) up to the study's widest width
        ax.axvspan(lo, hi, color="tab:blue", alpha=0.05, lw=0)
        xs = np.geomspace(lo * 1.1, hi / 1.1, max(len(points), 1))
        for k, ((profile, m), x) in enumerate(zip(points, xs)):
            ax.errorbar([x], [100 * m.accuracy], yerr=[[100 * (m.accuracy - m.interval[0])],
                                                         [100 * (m.interval[1] - m.accuracy)]],
                        fmt="o", ms=3, color=colours[k % len(colours)], capsize=2,
                        label=f"{m.reader} ({profile}, n={m.n_plates})")
        study_points = _reader_study_points(readers, name, record.get("lens_spec"))
        marks = {r: ("s", colours[(len(points) + k) % len(colours)])
                 for k, r in enumerate(dict.fromkeys(r for r, _ in study_points))}
        for reader, b in study_points:
            x = _bin_centre_px(b["low_px"], b["high_px"]) * (0.97 if reader == "lpdr-oracle" else 1.03)
            acc, (lo_acc, hi_acc) = 100 * b["accuracy"], (100 * v for v in b["interval"])
            ax.errorbar([x], [acc], yerr=[[acc - lo_acc], [hi_acc - acc]], fmt=marks[reader][0], ms=3.5,
                        color=marks[reader][1], capsize=2, mfc="none")
        for reader, (marker, colour) in marks.items():
            n = sum(b["n_plates"] for r, b in study_points if r == reader)
            ax.plot([], [], marker, color=colour, mfc="none", label=f"{reader} per width bin (reader study, n={n})")
        ax.set_xscale("log")
        ax.set_xticks([4, 8, 16, 32, 64, 128])
        ax.set_xticklabels(["4", "8", "16", "32", "64", "128"])
        ax.xaxis.set_minor_formatter(matplotlib.ticker.NullFormatter())
        ax.set_xlim(3.5, 190)
        ax.set_ylim(-2, 102)
        ax.set_xlabel("plate width (px)")
        ax.set_title(name if points or study_points else f"{name} (no matching entry)", fontsize=9)
        ax.legend(fontsize=4.5, loc="upper center", bbox_to_anchor=(0.5, -0.22), ncol=2, frameon=False)
    panels[0].set_ylabel("plate read exactly (%)")
    bottom.suptitle("Ceiling (T=1, 95 % band) against the readers' accuracy over all readable plates "
                    "(Wilson 95 %)", fontsize=9)
    return fig


def write_ideal_observer_chart(study: dict, entries: Sequence[Entry], path: Path, readers: dict | None = None
                               ) -> Path:
    """Save `ideal_observer_figure` to `path` (PNG, under a leaderboard's charts/); returns the path.
    `readers` None: the reader study beside it (../studies/ideal_observer_readers.json) when there is one."""
    if readers is None:
        stored = Path(path).parent.parent / READER_STUDY
        readers = json.loads(stored.read_text(encoding="utf-8")) if stored.is_file() else None
    return save_figure(ideal_observer_figure(study, entries, readers), path, layout=False)
