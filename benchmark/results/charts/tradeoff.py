"""Utility against privacy: one panel per profile, the ensemble's figure per lens (the same figure as the
tables': plates read by any reader chain, pooled from the readable width, or each scene at its best
restorer) with its interval as error bars, the bracket up to the ideal observer's ceiling on the same
plates where the study covers the lens, labels in a column with leader lines (never overlapping), the
Pareto front."""

from __future__ import annotations

import dataclasses
from collections.abc import Mapping, Sequence
from pathlib import Path
from typing import Any

import matplotlib
from matplotlib.figure import Figure

from benchmark.results.charts import new_figure, save_figure
from benchmark.results.charts.point_labels import LABEL_FONT_PT, label_points, line_height_in
from benchmark.results import pooled
from benchmark.results.attack_gap import pooled_bracket
from benchmark.results.ensemble import plate_ensemble, scene_ensemble
from benchmark.results.entries import Entry
from benchmark.results.pooled import Pooled

_MARKERS = "osD^v<>pP*Xh"
# The x axes of the two trade-off charts, the PNGs' and the web page's alike.
PLATES_LABEL = "plates read by the ensemble % (from the readable width)"
PSNR_LABEL = "ensemble PSNR dB (each scene at its best restorer)"
# Panel geometry in inches: the label column sits right of the axes, outside them.
_LEFT_IN, _AXES_W_IN, _LABELS_W_IN = 0.85, 5.2, 2.3
_TOP_IN, _BOTTOM_IN, _MIN_AXES_H_IN = 0.45, 0.65, 2.8
# Narrowest axis spans: x in dB or %, y in mIoU.
_MIN_X_SPAN, _MIN_Y_SPAN = 2.0, 0.02


@dataclasses.dataclass(frozen=True)
class TradeoffPoint:
    """One lens of one profile: utility (mIoU) against its ensemble's privacy figure.

    ``*_low``/``*_high`` bound the error bar: the pooled 95 % interval (benchmark.results.pooled), or
    no bar where the rows carry no per-unit outcomes (``error`` says which). ``ceiling``: the ideal
    observer's pooled ceiling on the same plates (``attack_gap.pooled_bracket``), None where there is none."""

    lens: str
    profile: str
    scenes: str
    attacker: str
    privacy: float
    privacy_low: float
    privacy_high: float
    utility: float
    utility_low: float
    utility_high: float
    error: str
    ceiling: float | None = None


def _bounds(found: Pooled, scale: float) -> tuple[float, float, str]:
    """The pooled 95 % interval (benchmark.results.pooled), or no bar where there are no per-unit outcomes."""
    if found.interval is not None:
        return found.interval[0] * scale, found.interval[1] * scale, "pooled 95 % interval"
    return found.value * scale, found.value * scale, f"no bar: no {found.missing}"


def _of(n: int, what: str) -> str:
    return f"ensemble of {n} {what}{'' if n == 1 else 's'}"


def _ensemble_figure(e: Entry, privacy: str) -> tuple[Pooled, str] | None:
    """The ensemble's pooled figure and what it counts ("ensemble of 6 chains"), as the tables show it."""
    if privacy == "plate_acc":
        ensemble = plate_ensemble(e.rows)
        found = pooled.plates(e) if ensemble is not None else None
        return None if found is None else (found, _of(len(ensemble.chains), "chain"))  # type: ignore[union-attr]
    scenes = scene_ensemble(e.rows, privacy)
    if scenes is None:
        return None
    return (Pooled(scenes.mean, scenes.interval, scenes.seed_std, len(scenes.seed_values)),
            _of(len(scenes.restorers), "restorer"))


def tradeoff_points(entries: Sequence[Entry], privacy: str, scale: float = 1.0,
                    study: Mapping[str, Any] | None = None) -> list[TradeoffPoint]:
    """Points of every entry with a utility figure and an ensemble figure `privacy` ("plate_acc": plates read
    by any reader chain; "psnr_db": each scene at its best restorer), scaled by `scale` (100 for a fraction
    shown in %), each pooled over its units and seeds with its pooled 95 % interval as the bar
    (benchmark.results.pooled); plate points carry the pooled ceiling where `study` covers the lens."""
    points = []
    for e in entries:
        util = pooled.miou(e)
        found = _ensemble_figure(e, privacy)
        if util is None or found is None:
            continue
        figure, attacker = found
        (u_lo, u_hi, u_err), (p_lo, p_hi, p_err) = _bounds(util, 1.0), _bounds(figure, scale)
        bracket = pooled_bracket(e, study) if privacy == "plate_acc" else None
        points.append(TradeoffPoint(e.lens, e.profile, e.scenes, attacker, figure.value * scale, p_lo, p_hi,
                                    util.value, u_lo, u_hi, u_err if u_err == p_err else f"{p_err} / {u_err}",
                                    None if bracket is None else bracket.ceiling * scale))
    return points


def pareto_front(points: list[tuple[float, float]]) -> list[int]:
    """Indices of points not dominated when minimising x (attacker strength) and maximising y (utility)."""
    front = []
    for i, (x, y) in enumerate(points):
        if not any((x2 <= x and y2 >= y) and (x2 < x or y2 > y) for j, (x2, y2) in enumerate(points) if j != i):
            front.append(i)
    return sorted(front, key=lambda i: points[i][0])


def _limits(low: list[float], high: list[float], min_span: float) -> tuple[float, float]:
    """Axis range from the data: the error bars' extent plus 8 % on each side, at least ``min_span``
    wide (points that all agree, e.g. five lenses at 0 % plate accuracy, still get a readable axis)."""
    lo, hi = min(low), max(high)
    pad = max(0.08 * (hi - lo), (min_span - (hi - lo)) / 2)
    return lo - pad, hi + pad


def tradeoff_figure(points: Sequence[TradeoffPoint], xlabel: str) -> Figure:
    """One panel per profile (budgets are not comparable); lens colour and marker are the same in every panel."""
    if not points:
        raise ValueError("no trade-off points: entries need a utility row and an attacker figure")
    profiles = list(dict.fromkeys(p.profile for p in points))
    lenses = sorted({p.lens for p in points})
    colours = {lens: matplotlib.colormaps["tab20"](i % 20) for i, lens in enumerate(lenses)}
    markers = {lens: _MARKERS[i % len(_MARKERS)] for i, lens in enumerate(lenses)}
    heights = [max(_MIN_AXES_H_IN, sum(p.profile == prof for p in points) * line_height_in() + 0.3)
               for prof in profiles]
    width = _LEFT_IN + _AXES_W_IN + _LABELS_W_IN
    total = sum(h + _TOP_IN + _BOTTOM_IN for h in heights)
    fig = new_figure(figsize=(width, total))
    top = total
    for profile, axes_h in zip(profiles, heights):
        members = [p for p in points if p.profile == profile]
        bottom = top - _TOP_IN - axes_h
        ax = fig.add_axes((_LEFT_IN / width, bottom / total, _AXES_W_IN / width, axes_h / total))
        top = bottom - _BOTTOM_IN
        for p in members:
            ax.errorbar(p.privacy, p.utility, xerr=[[p.privacy - p.privacy_low], [p.privacy_high - p.privacy]],
                        yerr=[[p.utility - p.utility_low], [p.utility_high - p.utility]], fmt=markers[p.lens],
                        color=colours[p.lens], capsize=3, ms=6, lw=1)
            if p.ceiling is not None:  # the bracket: what the ideal observer reads of the same plates
                ax.plot([p.privacy, p.ceiling], [p.utility, p.utility], ":", color=colours[p.lens], lw=1)
                ax.plot([p.ceiling], [p.utility], markers[p.lens], mfc="none", color=colours[p.lens], ms=6)
        front = [members[i] for i in pareto_front([(p.privacy, p.utility) for p in members])]
        ax.plot([p.privacy for p in front], [p.utility for p in front], "--", color="grey", lw=1, label="Pareto front")
        ax.set_xlim(*_limits([p.privacy_low for p in members],
                             [max(p.privacy_high, p.ceiling or p.privacy_high) for p in members], _MIN_X_SPAN))
        ax.set_ylim(*_limits([p.utility_low for p in members], [p.utility_high for p in members], _MIN_Y_SPAN))
        ax.set_xlabel(xlabel + " (lower = more private)")
        ax.set_ylabel("utility mIoU (higher = more useful)")
        errors = ", ".join(sorted({p.error for p in members}))
        if any(p.ceiling is not None for p in members):
            errors += "; open = ceiling, same plates"
        ax.set_title(f"profile {profile}, scenes {', '.join(dict.fromkeys(p.scenes for p in members))}: "
                     f"error bars = {errors}", fontsize=9, loc="left")
        ax.grid(alpha=0.3)
        ax.legend(fontsize=7, loc="lower right")
        label_points(ax, [(p.privacy, p.utility) for p in members], [p.lens for p in members],
                     [colours[p.lens] for p in members], axes_h, LABEL_FONT_PT)
    return fig


def write_tradeoff_chart(entries: Sequence[Entry], path: Path, privacy: str, xlabel: str, scale: float = 1.0,
                         study: Mapping[str, Any] | None = None) -> Path | None:
    """Write the trade-off chart of `privacy` (see tradeoff_points) to `path`; None when no entry has one."""
    points = tradeoff_points(entries, privacy, scale, study)
    if not points:
        return None
    return save_figure(tradeoff_figure(points, xlabel), path, dpi=100, layout=False)
