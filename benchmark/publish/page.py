"""leaderboard/index.html: a self-contained static page of the leaderboard (no server, no network).

Everything is inline (style, vanilla script, the utility-vs-privacy charts as SVG); the only
external references are the leaderboard's own PNGs, by relative path. The trade-off table has one
line per entry and threat model: "any attacker" (the markdown table's line) and, for each threat
model, the worst case among that threat model's attackers only. Selecting a profile, scene set or
threat model hides the other lines and chart points (one chart per profile and privacy figure);
clicking a column header sorts by it. The first screen holds, per profile, the takeaway, the chart of
utility against the plates the ensemble reads (intervals, Pareto front, the bracket up to the ideal
observer's ceiling on the same plates) beside the headline table, and the entries shown apart (another
version, benchmark.publish.versions).
"""

from __future__ import annotations

import dataclasses
import html
from collections.abc import Mapping, Sequence
from pathlib import Path
from typing import Any

from matplotlib.ticker import MaxNLocator

from benchmark.store.cache import atomic_write_text
from benchmark.results.charts.tradeoff import PLATES_LABEL, PSNR_LABEL, TradeoffPoint, pareto_front, tradeoff_points
from benchmark.results.entries import Entry, file_safe
from benchmark.publish.tables import (CONVENTION, FINDINGS_HEAD, PRIVATE_LEVEL, Column, findings_lines,
                                      headline_columns, table_columns, takeaways)

ANY_THREAT = "any attacker"
# Colour per lens, in order of first appearance (colour-blind-safe "Tableau 10").
_PALETTE = ("#4e79a7", "#f28e2b", "#e15759", "#76b7b2", "#59a14f", "#edc948", "#b07aa1", "#ff9da7", "#9c755f",
            "#bab0ac")
_SVG_W, _SVG_H, _PAD_L, _PAD_R, _PAD_T, _PAD_B = 620, 400, 64, 16, 16, 48

_STYLE = """
body{font-family:system-ui,-apple-system,"Segoe UI",sans-serif;margin:1.5rem auto;max-width:1200px;padding:0 1rem;
color:#222;line-height:1.4}
h1{margin-bottom:.2rem}h2{margin-top:2rem;border-bottom:1px solid #ddd}
table{border-collapse:collapse;font-size:.85rem;margin:.5rem 0}
th,td{border:1px solid #ddd;padding:.25rem .45rem;text-align:left;vertical-align:top}
th{background:#f4f4f4}table.sortable th{cursor:pointer;user-select:none}
table.sortable th[aria-sort=ascending]::after{content:" \\25B2"}
table.sortable th[aria-sort=descending]::after{content:" \\25BC"}
tbody tr:nth-child(even){background:#fafafa}
.filters{display:flex;gap:1rem;flex-wrap:wrap;margin:.5rem 0}.filters label{font-size:.9rem}
.charts,.first{display:flex;gap:1.5rem;flex-wrap:wrap;align-items:flex-start}
.first figure{max-width:470px}.first svg{width:470px;height:auto}svg text.label{font-size:10px}figure{margin:0}figcaption{font-size:.85rem;color:#555}
svg .point{cursor:pointer}svg .axis{stroke:#444}svg .grid{stroke:#e6e6e6}svg text{font-size:11px;fill:#333}
#tip{position:absolute;display:none;background:#fff;border:1px solid #888;border-radius:4px;padding:.3rem .5rem;
font-size:.8rem;white-space:pre;pointer-events:none;box-shadow:0 2px 6px rgba(0,0,0,.2)}
table.headline th,table.headline td{white-space:nowrap}table.headline td:not(:first-child){text-align:right}
.takeaway{max-width:70rem}.legend{font-size:.8rem;color:#444;max-width:75rem}.legend dt{font-weight:600;display:inline}
.legend dd{display:inline;margin:0 0 0 .3rem}.legend dd::after{content:"";display:block}
details.more>summary{font-size:1.15rem;font-weight:600;margin:1.5rem 0 .5rem}
.alarm{color:#b00020}tr.violation{background:#fde7e9}img{max-width:100%}details{margin:.3rem 0}summary{cursor:pointer}.count{color:#555;font-size:.85rem}
"""

_SCRIPT = """
(function () {
  "use strict";
  function sortKey(td) {
    var v = td.getAttribute("data-sort");
    if (v === null || v === "") { return null; }
    var n = Number(v);
    return isNaN(n) ? v : n;
  }
  document.querySelectorAll("table.sortable").forEach(function (table) {
    var heads = table.tHead.rows[0].cells;
    Array.prototype.forEach.call(heads, function (th, col) {
      th.addEventListener("click", function () {
        var ascending = th.getAttribute("aria-sort") !== "ascending";
        Array.prototype.forEach.call(heads, function (h) { h.removeAttribute("aria-sort"); });
        th.setAttribute("aria-sort", ascending ? "ascending" : "descending");
        var body = table.tBodies[0];
        var rows = Array.prototype.slice.call(body.rows);
        rows.sort(function (a, b) {
          var x = sortKey(a.cells[col]), y = sortKey(b.cells[col]);
          if (x === null || y === null) { return (x === null) - (y === null); }  /* empty cells last */
          var c = (typeof x === "number" && typeof y === "number") ? x - y : String(x).localeCompare(String(y));
          return ascending ? c : -c;
        });
        rows.forEach(function (r) { body.appendChild(r); });
      });
    });
  });
  var filters = document.querySelectorAll("select[data-filter]");
  function applyFilters() {
    var want = {};
    filters.forEach(function (s) { want[s.getAttribute("data-filter")] = s.value; });
    var shown = 0;
    document.querySelectorAll("[data-filtered]").forEach(function (el) {
      var keep = Object.keys(want).every(function (k) {
        return want[k] === "*" || !el.hasAttribute("data-" + k) || el.getAttribute("data-" + k) === want[k];
      });
      el.style.display = keep ? "" : "none";
      if (keep && el.tagName === "TR") { shown += 1; }
    });
    document.getElementById("shown").textContent = shown + " of " +
      document.querySelectorAll("#tradeoff tbody tr[data-threat='" + want.threat + "']").length + " lines shown";
  }
  filters.forEach(function (s) { s.addEventListener("change", applyFilters); });
  applyFilters();
  var tip = document.getElementById("tip");
  document.querySelectorAll("svg .point").forEach(function (p) {
    p.addEventListener("mouseenter", function (ev) {
      tip.textContent = p.getAttribute("data-tip");
      tip.style.display = "block";
      tip.style.left = (ev.pageX + 12) + "px";
      tip.style.top = (ev.pageY + 12) + "px";
    });
    p.addEventListener("mouseleave", function () { tip.style.display = "none"; });
  });
})();
"""


def _e(text: object) -> str:
    return html.escape(str(text), quote=True)


def threat_views(entry: Entry) -> list[tuple[str, set[str] | None]]:
    """(threat model, attack chains it allows) for the entry: every attacker, then each threat model's own."""
    models = sorted({c.threat_model for c in entry.chains() if c.threat_model})
    return [(ANY_THREAT, None)] + [(m, {c.attack for c in entry.chains() if c.threat_model == m}) for m in models]


def _filter_attrs(profile: str, scenes: str, threat: str) -> str:
    return f'data-filtered="1" data-profile="{_e(profile)}" data-scenes="{_e(scenes)}" data-threat="{_e(threat)}"'


def _th(column: Column) -> str:
    return f'<th title="{_e(column.tip)}">{_e(column.header)}</th>' if column.tip else f"<th>{_e(column.header)}</th>"


def headline_html(entries: Sequence[Entry], study: Mapping[str, Any] | None = None,
                  charts: Mapping[str, str] | None = None, apart: Sequence[Any] = ()) -> str:
    """The first screen: per profile its takeaway (generated, tables.takeaways), its chart (`charts`: SVG by
    profile) beside a table of the headline columns only (tables.headline_columns), every header with its
    tooltip, the entries shown apart (`apart`: ``versions.Apart``), then one legend of the columns."""
    columns = headline_columns(study)
    said = takeaways(entries, study)
    parts = []
    for profile in dict.fromkeys(e.profile for e in entries):
        mine = [e for e in entries if e.profile == profile]
        scenes = ", ".join(dict.fromkeys(e.scenes for e in mine))
        lines = []
        for e in mine:
            tds = "".join(f'<td data-sort="{_e(text if value is None else repr(value))}">{_e(text)}</td>'
                          for text, value in (c.cell(e, None) for c in columns))
            lines.append(f"<tr>{tds}</tr>")
        takeaway = said.get(profile)
        others = [a for a in apart if a.entry.profile == profile]
        parts.append(
            f'<section class="profile" data-profile="{_e(profile)}"><h2>Profile {_e(profile)} '
            f'<span class="count">(scenes {_e(scenes)}; {len(mine)} lenses)</span></h2>'
            + (f'<p class="takeaway"><strong>Takeaway.</strong> {_e(takeaway)}</p>' if takeaway else "")
            + '<div class="first">' + (charts or {}).get(profile, "")
            + f'<table class="headline sortable" data-profile="{_e(profile)}"><thead><tr>'
            + "".join(_th(c) for c in columns) + "</tr></thead><tbody>" + "".join(lines) + "</tbody></table></div>"
            + ('<p class="apart"><strong>Shown apart</strong> (another version than this board\'s; in no takeaway, '
               "front, chart or finding until re-published): "
               + ", ".join(f'<span title="{_e(a.reason)}">{_e(a.entry.lens)} ({_e(", ".join(a.fields))})</span>'
                           for a in others) + " differ; hover a lens for how.</p>" if others else "")
            + "</section>")
    legend = "".join(f"<dt>{_e(c.header)}</dt><dd>{_e(c.tip)}</dd>" for c in columns)
    return "".join(parts) + f'<dl class="legend">{legend}</dl>'


def tradeoff_table(entries: Sequence[Entry], study: Mapping[str, Any] | None = None) -> str:
    """The sortable trade-off table: the columns of the markdown table (`table_columns(study)`) plus
    the threat model, one line per entry and threat view."""
    columns = table_columns(study, entries)
    head = "".join(_th(c) for c in columns[:4])
    head += '<th title="the attackers the privacy columns count: every one, or one threat model\'s">threat model</th>'
    head += "".join(_th(c) for c in columns[4:])
    lines = []
    for e in entries:
        for threat, attacks in threat_views(e):
            cells = [c.cell(e, attacks) for c in columns]
            cells = cells[:4] + [(threat, None)] + cells[4:]
            tds = "".join(f'<td data-sort="{_e(text if value is None else repr(value))}">{_e(text)}</td>'
                          for text, value in cells)
            lines.append(f"<tr {_filter_attrs(e.profile, e.scenes, threat)}>{tds}</tr>")
    return (f'<table id="tradeoff" class="sortable"><thead><tr>{head}</tr></thead><tbody>\n'
            + "\n".join(lines) + "\n</tbody></table>")


def _scale(lo: float, hi: float, a: float, b: float):
    span = (hi - lo) or 1.0
    return lambda v: a + (v - lo) / span * (b - a)


def _range(values: list[float]) -> tuple[float, float]:
    lo, hi = min(values), max(values)
    pad = 0.06 * (hi - lo) if hi > lo else max(abs(hi) * 0.05, 1e-3)
    return lo - pad, hi + pad


def tradeoff_svg(points: Sequence[tuple[TradeoffPoint, str]], xlabel: str, unit: str, colours: dict[str, str]) -> str:
    """Inline SVG of utility against privacy; each point (with its error bars) carries the filter
    attributes and a hover text naming lens, attacker and both intervals. ``points`` pairs a point
    with its threat view."""
    xr = _range([v for p, _ in points for v in (p.privacy_low, p.privacy_high, p.ceiling) if v is not None])
    yr = _range([v for p, _ in points for v in (p.utility_low, p.utility_high)])
    sx = _scale(*xr, _PAD_L, _SVG_W - _PAD_R)
    sy = _scale(*yr, _SVG_H - _PAD_B, _PAD_T)
    parts = [f'<svg xmlns="http://www.w3.org/2000/svg" width="{_SVG_W}" height="{_SVG_H}" '
             f'viewBox="0 0 {_SVG_W} {_SVG_H}" role="img" aria-label="{_e(xlabel)}">']
    for tick in MaxNLocator(6).tick_values(*xr):
        if xr[0] <= tick <= xr[1]:
            x = sx(tick)
            parts.append(f'<line class="grid" x1="{x:.1f}" y1="{_PAD_T}" x2="{x:.1f}" y2="{_SVG_H - _PAD_B}"/>'
                         f'<text x="{x:.1f}" y="{_SVG_H - _PAD_B + 16}" text-anchor="middle">{tick:g}</text>')
    for tick in MaxNLocator(6).tick_values(*yr):
        if yr[0] <= tick <= yr[1]:
            y = sy(tick)
            parts.append(f'<line class="grid" x1="{_PAD_L}" y1="{y:.1f}" x2="{_SVG_W - _PAD_R}" y2="{y:.1f}"/>'
                         f'<text x="{_PAD_L - 6}" y="{y + 4:.1f}" text-anchor="end">{tick:g}</text>')
    parts.append(f'<line class="axis" x1="{_PAD_L}" y1="{_SVG_H - _PAD_B}" x2="{_SVG_W - _PAD_R}" '
                 f'y2="{_SVG_H - _PAD_B}"/><line class="axis" x1="{_PAD_L}" y1="{_PAD_T}" x2="{_PAD_L}" '
                 f'y2="{_SVG_H - _PAD_B}"/>')
    parts.append(f'<text x="{(_PAD_L + _SVG_W - _PAD_R) / 2}" y="{_SVG_H - 10}" text-anchor="middle">'
                 f'{_e(xlabel)} (lower = more private)</text>')
    parts.append(f'<text transform="translate(14 {(_SVG_H - _PAD_B + _PAD_T) / 2}) rotate(-90)" '
                 f'text-anchor="middle">utility mIoU (higher = more useful)</text>')
    every = [p for p, threat in points if threat == ANY_THREAT]
    front = [every[i] for i in pareto_front([(p.privacy, p.utility) for p in every])]
    if len(front) > 1:
        path = " ".join(f"{sx(p.privacy):.1f},{sy(p.utility):.1f}" for p in front)
        parts.append(f'<polyline class="front" points="{path}" fill="none" stroke="#888" stroke-dasharray="5 4">'
                     "<title>Pareto front (every attacker)</title></polyline>")
    for p, threat in points:
        ceiling = "" if p.ceiling is None else f"\nideal observer's ceiling on the same plates: {p.ceiling:.3g}{unit}"
        tip = (f"{p.lens} ({p.profile}, {p.scenes}; {threat})\n{p.attacker}\n"
               f"{xlabel}: {p.privacy:.3g}{unit} [{p.privacy_low:.3g}, {p.privacy_high:.3g}]{ceiling}\n"
               f"mIoU: {p.utility:.3f} [{p.utility_low:.3f}, {p.utility_high:.3f}]\nbars: {p.error}")
        x, y, colour = sx(p.privacy), sy(p.utility), colours[p.lens]
        bracket = ("" if p.ceiling is None else
                   f'<line x1="{x:.1f}" y1="{y:.1f}" x2="{sx(p.ceiling):.1f}" y2="{y:.1f}" stroke-dasharray="2 3"/>'
                   f'<circle cx="{sx(p.ceiling):.1f}" cy="{y:.1f}" r="5" fill="none"/>')
        parts.append(
            f'<g class="point" {_filter_attrs(p.profile, p.scenes, threat)} data-lens="{_e(p.lens)}" '
            f'data-tip="{_e(tip)}" stroke="{colour}">'
            f'<line x1="{sx(p.privacy_low):.1f}" y1="{y:.1f}" x2="{sx(p.privacy_high):.1f}" y2="{y:.1f}"/>'
            f'<line x1="{x:.1f}" y1="{sy(p.utility_low):.1f}" x2="{x:.1f}" y2="{sy(p.utility_high):.1f}"/>'
            f'<circle cx="{x:.1f}" cy="{y:.1f}" r="5" fill="{colour}" fill-opacity="0.8"/>{bracket}'
            f'<text class="label" x="{x + 7:.1f}" y="{y - 7:.1f}" stroke="none">{_e(p.lens)}</text></g>')
    parts.append("</svg>")
    return "".join(parts)


def _points_by_threat(entries: Sequence[Entry], privacy: str, scale: float, study: Mapping[str, Any] | None = None
                      ) -> list[tuple[TradeoffPoint, str]]:
    out = []
    for e in entries:
        for threat, attacks in threat_views(e):
            view = e if attacks is None else _restricted(e, attacks)
            out += [(p, threat) for p in tradeoff_points([view], privacy, scale, study)]
    return out


def _restricted(entry: Entry, attacks: set[str]) -> Entry:
    """The entry with only the given attack chains (and its lens, utility and bound rows)."""
    keep = [r for r in entry.rows if r.attack in attacks or r.kind in ("lens", "utility", "bound")]
    return dataclasses.replace(entry, rows=keep)


def _options(name: str, label: str, values: Sequence[str], default: str, with_all: bool) -> str:
    opts = ['<option value="*">all</option>'] if with_all else []
    opts += [f'<option value="{_e(v)}"{" selected" if v == default else ""}>{_e(v)}</option>' for v in values]
    return f'<label>{_e(label)} <select data-filter="{name}" id="filter-{name}">{"".join(opts)}</select></label>'


def findings_html(entries: Sequence[Entry]) -> str:
    lines = findings_lines(entries)
    if not lines:
        return "<p>No paper finding applies to these entries (they need both lenses of a claim in one profile).</p>"
    head = "".join(f"<th>{_e(h)}</th>" for h in FINDINGS_HEAD)
    rows = "".join("<tr>" + "".join(f"<td>{_e(cell)}</td>" for cell in line) + "</tr>" for line in lines)
    return f"<table><thead><tr>{head}</tr></thead><tbody>{rows}</tbody></table>"


def violations_html(found: Sequence[tuple[Entry, Any]]) -> str:
    """The "Ceiling violations" section's body: every reader above its lens's ideal-observer ceiling."""
    if not found:
        return ("<p>None: every reader of every entry whose lens the ideal-observer study covers reads at or below "
                "its ceiling (T = 1, upper 95 % limit; accuracy over all readable plates, Wilson 95 %).</p>")
    rows = "".join(f'<tr class="violation"><td>{_e(e.lens)}</td><td>{_e(e.profile)}</td><td>{_e(e.scenes)}</td>'
                   f"<td>{_e(v.measured.reader)}</td><td>{100 * v.measured.accuracy:.1f}</td>"
                   f"<td>{100 * v.measured.interval[0]:.1f}-{100 * v.measured.interval[1]:.1f}</td>"
                   f"<td>{v.measured.n_plates}</td><td>{100 * v.ceiling_high:.1f}</td></tr>" for e, v in found)
    return (f'<p class="alarm"><strong>{len(found)} reader(s) beat the ideal observer\'s ceiling: a modelling or '
            "scoring error (benchmark.results.observer.consistency).</strong></p><table><thead><tr><th>lens</th>"
            "<th>profile</th><th>scenes</th><th>reader</th><th>plate acc %</th><th>95 % interval</th><th>plates</th>"
            f"<th>ceiling % (upper 95 %)</th></tr></thead><tbody>{rows}</tbody></table>")


def flags_html(flags: Sequence[Any]) -> str:
    """The "Attack flags" section's body (benchmark.results.attack_gap.Flag), or a line saying there is none."""
    if not flags:
        return "<p>None.</p>"
    rows = "".join(f'<tr class="violation"><td>{_e(f.lens)}</td><td>{_e(f.profile)}</td><td>{_e(f.kind)}</td>'
                   f"<td>{_e(f.message)}</td></tr>" for f in flags)
    return ("<table><thead><tr><th>lens</th><th>profile</th><th>flag</th><th>what</th></tr></thead>"
            f"<tbody>{rows}</tbody></table>")


def _svg_figure(profile: str, points: Sequence[tuple[TradeoffPoint, str]], label: str, unit: str,
                colours: dict[str, str]) -> str:
    return (f'<figure data-filtered="1" data-profile="{_e(profile)}">{tradeoff_svg(points, label, unit, colours)}'
            f"<figcaption>Profile {_e(profile)}: utility against {_e(label)} (the tables' figure, 95 % intervals; "
            "dashed: the Pareto front; open circle: what the ideal observer reads of the same plates); hover a "
            "point for the lens and the intervals.</figcaption></figure>")


def page_html(entries: Sequence[Entry], charts: Sequence[Path], pictures: Sequence[Path],
              study: Mapping[str, Any] | None = None, violations: Sequence[tuple[Entry, Any]] = (),
              flags: Sequence[Any] = (), apart: Sequence[Any] = ()) -> str:
    """The whole page as text (deterministic: the same entries give the same bytes); `study`: the
    ideal-observer study, `violations`: the readers above its ceilings (benchmark.results.observer.published),
    `apart`: the entries of another version (benchmark.publish.versions), listed but not compared."""
    lenses = list(dict.fromkeys(e.lens for e in entries))
    colours = {lens: _PALETTE[i % len(_PALETTE)] for i, lens in enumerate(lenses)}
    threats = [ANY_THREAT] + sorted({t for e in entries for t, _ in threat_views(e)} - {ANY_THREAT})
    filters = "".join([
        _options("profile", "profile", list(dict.fromkeys(e.profile for e in entries)), "*", True),
        _options("scenes", "scenes", list(dict.fromkeys(e.scenes for e in entries)), "*", True),
        _options("threat", "threat model", threats, ANY_THREAT, False)])
    first, svgs = {}, []
    for privacy, scale, label, unit in (("plate_acc", 100.0, PLATES_LABEL, " %"), ("psnr_db", 1.0, PSNR_LABEL, " dB")):
        points = _points_by_threat(entries, privacy, scale, study)
        for profile in dict.fromkeys(p.profile for p, _ in points):  # budgets are not comparable: a chart each
            mine = [(p, t) for p, t in points if p.profile == profile]
            figure = _svg_figure(profile, mine, label, unit, colours)
            if privacy == "plate_acc":
                first[profile] = figure
            else:
                svgs.append(figure)
    samples = [p for p in pictures if not p.name.startswith("plate_width__")]
    per_lens = []
    apart_lenses = [a.entry.lens for a in apart if a.entry.lens not in lenses]
    for lens in dict.fromkeys([*lenses, *apart_lenses]):  # an entry shown apart keeps its pictures, marked
        # Pictures are `{lens}__{profile}[__curves].png`, the lens made file-safe (publish.leaderboard), which
        # may itself hold "__" (a spec path's "/[" become "__"): split from the right.
        mine = [p for p in samples if p.stem.removesuffix("__curves").rsplit("__", 1)[0] == file_safe(lens)]
        if mine:
            imgs = "".join(f'<p>{_e(p.stem)}</p><img loading="lazy" src="samples/{_e(p.name)}" alt="{_e(p.stem)}">'
                           for p in mine)
            mark = " (shown apart: another version)" if lens in apart_lenses else ""
            per_lens.append(f"<details><summary>{_e(lens)}{mark}</summary>{imgs}</details>")
    static = "".join(f'<figure><img loading="lazy" src="charts/{_e(p.name)}" alt="{_e(p.stem)}">'
                     f"<figcaption>{_e(p.stem)}</figcaption></figure>" for p in charts)
    return "\n".join([
        "<!DOCTYPE html>", '<html lang="en"><head><meta charset="utf-8">',
        '<meta name="viewport" content="width=device-width, initial-scale=1">',
        '<link rel="icon" href="data:,">', "<title>Privacy Lens Bench leaderboard</title>",
        f"<style>{_STYLE}</style></head><body>",
        "<h1>Privacy Lens Bench leaderboard</h1>",
        f'<p class="convention"><strong>Intervals.</strong> {_e(CONVENTION)}</p>',
        "<p>Which lens keeps most utility (mIoU, higher is better) for how much privacy (the plates the ensemble of "
        "every attacker of the suite reads, lower is better)? A plate counts as read when any attacker read it; "
        f"\"private\" below means under {100 * PRIVATE_LEVEL:g} % at the upper 95 % limit. Hover a column header "
        "for what it shows; click it to sort.</p>",
        headline_html(entries, study, first, apart),
        '<details class="more" id="more"><summary>Everything else: the full tables (every figure, filterable by '
        "profile, scenes and threat model), ceiling violations, attack flags, interactive charts, the paper's "
        "findings, samples and charts</summary>",
        "<p>Ensemble = every attacker of the suite for that lens, or of the chosen threat model, at once: a plate "
        "counts as read when any chain read it, a scene at its best restorer; worst case = the strongest single "
        "attacker (ranked on the seeds every attacker ran); attack gap = the ideal observer's ceiling minus the "
        "ensemble.</p>",
        f'<div class="filters">{filters}<span class="count" id="shown"></span></div>',
        "<h2>Utility against privacy</h2>", tradeoff_table(entries, study),
        "<h2>Ceiling violations</h2>", violations_html(violations),
        "<h2>Attack flags</h2>", flags_html(flags),
        f'<h2>Utility against restoration, interactive</h2><div class="charts">{"".join(svgs)}</div>',
        "<h2>The paper's findings on these entries</h2>", findings_html(entries),
        "<h2>Samples per lens</h2>", "".join(per_lens) or "<p>No published sample images.</p>",
        f'<h2>Charts</h2><div class="charts">{static}</div>', "</details>",
        '<div id="tip" role="tooltip"></div>', f"<script>{_SCRIPT}</script>", "</body></html>", ""])


def write_page(path: Path, entries: Sequence[Entry], charts: Sequence[Path], pictures: Sequence[Path],
               study: Mapping[str, Any] | None = None, violations: Sequence[tuple[Entry, Any]] = (),
               flags: Sequence[Any] = (), apart: Sequence[Any] = ()) -> Path:
    """Write the page to `path` (chart and picture paths are linked relative to its folder)."""
    atomic_write_text(path, page_html(entries, charts, pictures, study, violations, flags, apart))
    return path
