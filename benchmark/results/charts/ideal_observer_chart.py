"""The ideal observer's ceiling against plate width, per lens, with the leaderboard's readers on it.

Top: the plate ceiling (left) and the mean per-character ceiling (right) of every lens of the
study, T = 1 solid, T = 30 dashed, the PSF at each width's own distance dotted, the tighter
(marginalised) T = 1 ceiling as a dash-dot step over each width bin where the study holds it, the 5 % line.
Bottom: one panel per lens, its T = 1 genie plate ceiling with the 95 % band and T = 30 dashed, the
tighter ceiling as a step per width bin, and the entries whose lens spec the study matches. Where both
an entry's ensemble per width bin and the tighter ceiling exist, the privacy bracket [ensemble accuracy,
tighter ceiling] is shaded per bin in the ensemble's colour. An entry whose plates carry their widths draws its
ensemble's accuracy per width bin (a plate read by any chain, benchmark.results.ensemble; Wilson 95 %
intervals, bins of fewer than MIN_BIN_PLATES plates left out) as a line against the ceiling: the
attack gap at a glance. An older entry (no widths) draws every reader and chain's accuracy over all
readable plates, spread over the shaded widths it pools. As squares at each width bin's centre, the
reader study (leaderboard/studies/ideal_observer_readers.json: `ideal-observer` beside `lpdr-oracle`
on the same plates, per width bin with Wilson 95 % intervals) where its lens spec matches.
"""

from __future__ import annotations

import dataclasses
import json
from collections.abc import Sequence
from pathlib import Path

import matplotlib
import matplotlib.ticker
import numpy as np
from matplotlib.figure import Figure
from matplotlib.lines import Line2D

from benchmark.results.charts import new_figure, save_figure
from benchmark.results.charts.point_labels import wrap_label
from benchmark.results.ensemble import WidthBin, plate_ensemble
from benchmark.results.entries import Entry


READER_STUDY = Path("studies") / "ideal_observer_readers.json"


def _bin_centre_px(low_px: float, high_px: float | None) -> float:
    """Where a width bin's point is drawn: its geometric centre; an open last bin (high None or inf) at
    1.25 x its start."""
    return float(np.sqrt(low_px * high_px)) if high_px is not None and np.isfinite(high_px) else 1.25 * low_px


def _reader_study_points(readers: dict | None, name: str, spec: dict | None) -> list[tuple[str, dict]]:
    """(reader, bin) of the reader study for lens `name` when its spec there matches the ceiling's."""
    from benchmark.results.observer.published import same_lens
    if readers is None or not same_lens(readers.get("lens_specs", {}).get(name), spec):
        return []
    return [(reader, b) for reader, record in readers["lenses"].get(name, {}).items() for b in record["bins"]]


# Shown about 1000 px wide at DPI: FIG_W_IN inches are about 1.2 x the page, the fonts near their printed size.
DPI = 100
FONT_PT, LEGEND_PT = 10.0, 8.5
FIG_W_IN, _LEFT_IN, _RIGHT_IN = 12.0, 0.75, 0.15
_TOP_H_IN, _TOP_LEGEND_W_IN, _PANEL_H_IN, _PANEL_COLS = 3.2, 2.7, 2.1, 3
# A legend's height: 1.3 em per text line and 0.55 em between entries (matplotlib's labelspacing 0.5).
_HEADER_IN, _TITLE_IN, _XLABEL_IN, _LEGEND_LINE_IN = 0.45, 0.35, 0.5, LEGEND_PT / 72
# Per lens panel at most this many readers and chains are drawn in colour (the most accurate first); the
# others are grey points under one legend entry, so that a legend stays a few lines long.
MAX_READERS = 6
# An ensemble's width bin is drawn from this many plates (pooled over seeds): a smoke entry's one plate
# per bin and seed would draw intervals spanning most of the axis.
MIN_BIN_PLATES = 10
# Twelve distinct colours, no grey (grey is the "other readers" points' and the ceiling band's).
PALETTE = tuple([matplotlib.colormaps["tab10"](i) for i in range(10) if i != 7] + ["#393b79", "#8c6d31", "#637939"])


def _panel_points(points: list, max_readers: int = MAX_READERS) -> tuple[list, list]:
    """(drawn in colour, grouped in grey) of a panel's (profile, BinAccuracy) points: all when at most
    ``max_readers``, else the ``max_readers - 1`` most accurate (then by reader and profile)."""
    ranked = sorted(points, key=lambda pm: (-pm[1].accuracy, pm[1].reader, pm[0]))
    return (ranked, []) if len(ranked) <= max_readers else (ranked[:max_readers - 1], ranked[max_readers - 1:])


@dataclasses.dataclass(frozen=True)
class EnsembleCurve:
    """One entry's ensemble accuracy per width bin (those of at least MIN_BIN_PLATES plates)."""

    profile: str
    chains: int
    n_plates: int
    bins: tuple[WidthBin, ...]

    def label(self) -> str:
        return wrap_label(f"ensemble of {self.chains} chains per width bin ({self.profile}, n={self.n_plates})")


def ensemble_curve(entry: Entry) -> EnsembleCurve | None:
    """The entry's ensemble per width bin, or None where its plates carry no widths (older entries)."""
    ensemble = plate_ensemble(entry.rows)
    if ensemble is None or ensemble.bins is None:
        return None
    bins = tuple(b for b in ensemble.bins if b.accuracy.n >= MIN_BIN_PLATES)
    return EnsembleCurve(entry.profile, len(ensemble.chains), sum(b.accuracy.n for b in ensemble.bins), bins)


def ideal_observer_figure(study: dict, entries: Sequence[Entry] = (), readers: dict | None = None) -> Figure:
    """The chart of the module docstring; `study` is leaderboard/studies/ideal_observer.json, `readers`
    the reader study (ideal_observer_readers.json) or None. Lens panels are laid out _PANEL_COLS to a row,
    each with its legend under it; a panel draws at most MAX_READERS readers in colour, the rest grey."""
    from benchmark.results.observer.published import entry_accuracies, study_record
    names = list(study["lenses"])
    panels_data = []
    for name in names:
        record = study["lenses"][name]
        matching = [e for e in entries if e.lens == name and study_record(study, name, e.lens_spec) is not None]
        by_entry = [(e, ensemble_curve(e)) for e in matching]
        curves = [c for _, c in by_entry if c is not None and c.bins]
        points = [(e.profile, m) for e, c in by_entry if c is None for m in entry_accuracies(e)]
        study_points = _reader_study_points(readers, name, record.get("lens_spec"))
        shown, grouped = _panel_points(points)
        labels = [c.label() for c in curves]
        labels += [wrap_label(f"{m.reader} ({profile}, n={m.n_plates})") for profile, m in shown]
        labels += [wrap_label(f"{r} per width bin (reader study)") for r in dict.fromkeys(r for r, _ in study_points)]
        # The tighter ceiling's line and one bracket entry per ensemble curve (each about two lines).
        extra = (1 + len(curves)) if record.get("marginal", {}).get("t1") else 0
        n_entries = 2 + bool(grouped) + len(labels) + extra
        lines = n_entries + sum(label.count("\n") for label in labels) + extra
        panels_data.append((name, record, curves, shown, grouped, study_points, 1.3 * lines + 0.55 * n_entries))
    rows = [panels_data[i:i + _PANEL_COLS] for i in range(0, len(panels_data), _PANEL_COLS)]
    row_heights = [_TITLE_IN + _PANEL_H_IN + _XLABEL_IN + max(p[-1] for p in row) * _LEGEND_LINE_IN + 0.2
                   for row in rows]
    top_block = _HEADER_IN + _TITLE_IN + _TOP_H_IN + _XLABEL_IN
    height = top_block + _HEADER_IN + sum(row_heights)
    fig = new_figure(figsize=(FIG_W_IN, height))

    def axes_at(left_in: float, bottom_in: float, width_in: float, height_in: float, **kwargs):
        return fig.add_axes((left_in / FIG_W_IN, bottom_in / height, width_in / FIG_W_IN, height_in / height), **kwargs)

    # Top: the ceilings of every lens, whole plate and per character, the lens legend right of them.
    top_w = (FIG_W_IN - _LEFT_IN - _RIGHT_IN - _TOP_LEGEND_W_IN - 0.35) / 2
    top_bottom = height - _HEADER_IN - _TITLE_IN - _TOP_H_IN
    axes = [axes_at(_LEFT_IN, top_bottom, top_w, _TOP_H_IN)]
    axes.append(axes_at(_LEFT_IN + top_w + 0.35, top_bottom, top_w, _TOP_H_IN, sharey=axes[0]))
    colours = {name: PALETTE[n % len(PALETTE)] for n, name in enumerate(names)}
    for ax, key, title in zip(axes, ("plate", "char"), ("whole plate (least block)", "per character (mean)")):
        for name, record in study["lenses"].items():
            for frames, style in (("t1", "-"), ("t30", "--")):
                if frames in record:
                    curve = record[frames]["curve"]
                    ax.plot(curve["widths_px"], 100 * np.asarray(curve[f"{key}_ceiling"], dtype=float), style,
                            color=colours[name], lw=1.3, label=name if frames == "t1" else None)
            tighter = record.get("marginal", {}).get("t1")
            if tighter:
                step_x, step_y = _bin_steps(tighter["curve"], f"{key}_ceiling")
                ax.plot(step_x, step_y, "-.", color=colours[name], lw=1.1)
            deep = record.get("at_own_distance", {}).get("t1")
            if deep:
                ax.plot(deep["curve"]["widths_px"], 100 * np.asarray(deep["curve"][f"{key}_ceiling"], dtype=float),
                        ":", color=colours[name], lw=1.1)
        ax.axhline(100 * study["eps"], color="k", lw=0.8)
        _width_axis(ax)
        ax.set_title(f"Ceiling, {title}", fontsize=FONT_PT, loc="left")
    axes[1].tick_params(labelleft=False)
    axes[0].set_ylabel("ceiling on correct reads (%)", fontsize=FONT_PT)
    handles, labels = axes[0].get_legend_handles_labels()
    handles += [Line2D([], [], color="0.3", ls=ls) for ls in ("-", "--", ":", "-.")] + [Line2D([], [], color="k", lw=0.8)]
    labels += ["T = 1 (one frame)", "T = 30 frames", "PSF at own distance (T=1)",
               "tighter ceiling per bin (T=1)", f"{100 * study['eps']:g} % line"]
    axes[1].legend(handles, labels, loc="upper left", bbox_to_anchor=(1.03, 1.0), borderaxespad=0.0, frameon=False,
                   fontsize=LEGEND_PT, title="lens", title_fontsize=LEGEND_PT, alignment="left")
    fig.text(_LEFT_IN / FIG_W_IN, 1 - 0.1 / height, "Ideal-observer ceiling against plate width, every lens of the study",
             fontsize=FONT_PT + 2, ha="left", va="top")
    # Bottom: one panel per lens, the readers' accuracy against its T = 1 ceiling.
    fig.text(_LEFT_IN / FIG_W_IN, 1 - (top_block + 0.1) / height,
             "Per lens: the ceiling (T = 1, grey 95 % band) against what the attackers read (Wilson 95 %)",
             fontsize=FONT_PT + 1, ha="left", va="top")
    panel_w = (FIG_W_IN - _LEFT_IN - _RIGHT_IN - 0.3 * (_PANEL_COLS - 1)) / _PANEL_COLS
    row_top = height - top_block - _HEADER_IN
    first = None
    for row, row_h in zip(rows, row_heights):
        for col, (name, record, curves, shown, grouped, study_points, _) in enumerate(row):
            ax = axes_at(_LEFT_IN + col * (panel_w + 0.3), row_top - _TITLE_IN - _PANEL_H_IN, panel_w, _PANEL_H_IN,
                         **({"sharey": first} if first is not None else {}))
            first = first or ax
            _lens_panel(ax, record, curves, shown, grouped, study_points)
            matched = curves or shown or grouped or study_points
            ax.set_title(name if matched else f"{name} (no matching entry)", fontsize=FONT_PT)
            if col == 0:
                ax.set_ylabel("plate read exactly (%)", fontsize=FONT_PT)
            else:
                ax.tick_params(labelleft=False)
        row_top -= row_h
    return fig


def _bin_steps(curve: dict, key: str = "plate_ceiling") -> tuple[np.ndarray, np.ndarray]:
    """(x, y in %) of a marginalised curve drawn as a step over each of its width bins [w_k, high_k)."""
    lows = np.asarray(curve["widths_px"], dtype=float)
    highs = np.asarray(curve["width_high_px"], dtype=float)
    values = 100 * np.asarray(curve[key], dtype=float)
    return np.column_stack([lows, highs]).ravel(), np.repeat(values, 2)


def _tighter_in_bin(curve: dict, low_px: float) -> float | None:
    """The tighter ceiling (%) of the curve's bin holding `low_px`, None outside its bins."""
    lows = np.asarray(curve["widths_px"], dtype=float)
    highs = np.asarray(curve["width_high_px"], dtype=float)
    inside = np.flatnonzero((lows <= low_px) & (low_px < highs))
    return None if not len(inside) else 100 * float(curve["plate_ceiling"][int(inside[-1])])


def _width_axis(ax) -> None:
    """Log plate-width axis 3.5-260 px (an open last width bin is drawn at 1.25 x its start), ticks 4-192 px."""
    ax.set_xscale("log")
    ax.set_xticks([4, 8, 16, 32, 64, 128, 192])
    ax.set_xticklabels(["4", "8", "16", "32", "64", "128", "192"])
    ax.xaxis.set_minor_formatter(matplotlib.ticker.NullFormatter())
    ax.set_xlim(3.5, 260)
    ax.set_xlabel("plate width (px)", fontsize=FONT_PT - 1)
    ax.tick_params(labelsize=FONT_PT - 1)
    ax.grid(True, alpha=0.3)


def _lens_panel(ax, record: dict, curves: list[EnsembleCurve], shown: list, grouped: list, study_points: list
                ) -> None:
    """One lens: its T = 1 ceiling with the 95 % band, T = 30 dashed, the entries' ensembles per width bin
    (``curves``), older entries' readers (``shown`` in colour, ``grouped`` grey) spread over the readable
    widths, the reader study's squares per width bin."""
    curve = record["t1"]["curve"]
    widths = np.asarray(curve["widths_px"], dtype=float)
    band = np.asarray(curve["plate_interval"], dtype=float)
    ax.fill_between(widths, 100 * band[:, 0], 100 * band[:, 1], color="0.8", lw=0)
    ax.plot(widths, 100 * np.asarray(curve["plate_ceiling"], dtype=float), "k-", lw=1.2, label="ceiling T=1")
    if "t30" in record:
        t30 = record["t30"]["curve"]
        ax.plot(t30["widths_px"], 100 * np.asarray(t30["plate_ceiling"], dtype=float), "k--", lw=0.8,
                label="ceiling T=30")
    tighter = record.get("marginal", {}).get("t1", {}).get("curve")
    if tighter is not None:
        step_x, step_y = _bin_steps(tighter)
        ax.plot(step_x, step_y, "k-.", lw=1.1, label="tighter ceiling T=1 per bin (nuisances unknown)")
    for k, c in enumerate(curves):
        xs = [_bin_centre_px(b.low_px, b.high_px) for b in c.bins]
        acc = np.array([100 * b.accuracy.value for b in c.bins])
        low, high = (np.array([100 * b.accuracy.interval[i] for b in c.bins]) for i in (0, 1))
        colour = PALETTE[k % len(PALETTE)]
        ax.errorbar(xs, acc, yerr=[acc - low, high - acc], fmt="D-", ms=3.5, lw=1.3, capsize=2,
                    color=colour, label=c.label())
        for b, value in zip(c.bins, acc):
            top = None if tighter is None else _tighter_in_bin(tighter, b.low_px)
            if top is not None and np.isfinite(b.high_px):
                ax.fill_between([b.low_px, b.high_px], [value] * 2, [max(top, value)] * 2, color=colour, alpha=0.15,
                                lw=0)
        if tighter is not None and any(_tighter_in_bin(tighter, b.low_px) is not None for b in c.bins):
            ax.fill_between([], [], [], color=colour, alpha=0.15, lw=0,
                            label=wrap_label(f"privacy bracket [ensemble, tighter ceiling] ({c.profile})"))
    order = shown + grouped
    lo, hi = 32.0, 160.0  # an older entry's readable plates (>= 32 px) up to the study's widest width
    if order:
        ax.axvspan(lo, hi, color="tab:blue", alpha=0.05, lw=0)
    xs = np.geomspace(lo * 1.1, hi / 1.1, max(len(order), 1))
    for k, ((profile, m), x) in enumerate(zip(order, xs)):
        colour = PALETTE[(len(curves) + k) % len(PALETTE)] if k < len(shown) else "0.55"
        ax.errorbar([x], [100 * m.accuracy], yerr=[[100 * (m.accuracy - m.interval[0])],
                                                     [100 * (m.interval[1] - m.accuracy)]],
                    fmt="o", ms=3.5 if k < len(shown) else 2.5, color=colour, capsize=2, lw=1 if k < len(shown) else 0.7,
                    label=wrap_label(f"{m.reader} ({profile}, n={m.n_plates})") if k < len(shown) else None)
    if grouped:
        ax.plot([], [], "o", ms=2.5, color="0.55", label=wrap_label(f"{len(grouped)} other readers and chains (grey)"))
    marks = {r: ("s", PALETTE[(len(curves) + len(shown) + k) % len(PALETTE)])
             for k, r in enumerate(dict.fromkeys(r for r, _ in study_points))}
    for reader, b in study_points:
        x = _bin_centre_px(b["low_px"], b["high_px"]) * (0.97 if reader == "lpdr-oracle" else 1.03)
        acc, (lo_acc, hi_acc) = 100 * b["accuracy"], (100 * v for v in b["interval"])
        ax.errorbar([x], [acc], yerr=[[acc - lo_acc], [hi_acc - acc]], fmt=marks[reader][0], ms=3.5,
                    color=marks[reader][1], capsize=2, mfc="none")
    for reader, (marker, colour) in marks.items():
        n = sum(b["n_plates"] for r, b in study_points if r == reader)
        ax.plot([], [], marker, color=colour, mfc="none", label=wrap_label(f"{reader} per width bin (reader study, n={n})"))
    _width_axis(ax)
    ax.set_ylim(-2, 102)
    ax.legend(fontsize=LEGEND_PT, loc="upper left", bbox_to_anchor=(0.0, -_XLABEL_IN / _PANEL_H_IN), borderaxespad=0.0,
              frameon=False, handlelength=1.5)


def write_ideal_observer_chart(study: dict, entries: Sequence[Entry], path: Path, readers: dict | None = None
                               ) -> Path:
    """Save `ideal_observer_figure` to `path` (PNG, under a leaderboard's charts/); returns the path.
    `readers` None: the reader study beside it (../studies/ideal_observer_readers.json) when there is one."""
    if readers is None:
        stored = Path(path).parent.parent / READER_STUDY
        readers = json.loads(stored.read_text(encoding="utf-8")) if stored.is_file() else None
    return save_figure(ideal_observer_figure(study, entries, readers), path, dpi=DPI, layout=False)
