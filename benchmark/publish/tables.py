"""The leaderboard's tables, from its entries: the trade-off table, the findings and every attacker.

The trade-off table's columns are defined once (``table_columns``: ``MAIN_COLUMNS`` with the ideal
observer's beside the Fano bound's, then the attack gap's): the markdown table and the web page's
sortable table are both rendered from them. The ideal-observer cells come from
leaderboard/studies/ideal_observer.json and show only where the study's lens spec matches the entry's
(benchmark.results.observer.published); else "not computed".

The headline privacy columns are the ensemble's (benchmark.results.ensemble): a plate counts as read
when any reader chain read it, a scene at its best restorer; the strongest single chain and restorer
stay beside them. The attack gap (benchmark.results.attack_gap) is the ceiling minus the ensemble.
"""

from __future__ import annotations

import dataclasses
from collections.abc import Callable, Mapping, Sequence
from typing import Any

from benchmark.publish.findings import check_findings
from benchmark.results.attack_gap import GAP_WIDTHS_PX, Flag, entry_gaps
from benchmark.results.ensemble import chain_accuracy, plate_ensemble, scene_ensemble
from benchmark.results.entries import Entry, Stat
from benchmark.results.markdown import md_cell
from benchmark.results.observer.published import NOT_COMPUTED, study_record

# A cell: its text and the number it sorts by (None: empty).
Cell = tuple[str, float | None]


def pm(stat: Stat | None, digits: int = 3, pct: bool = False) -> str:
    """"mean ± seed std" (the std left out when it is 0, e.g. one seed); "" for no value."""
    if stat is None:
        return ""
    scale = 100.0 if pct else 1.0
    text = f"{stat.mean * scale:.{digits}f}"
    return text + (f" ± {stat.std * scale:.{digits}f}" if stat.std else "")


@dataclasses.dataclass(frozen=True)
class Column:
    """A trade-off table column: header and cell(entry, attacks) where `attacks` (None: all) limits
    the worst case to some attackers (the web page's threat-model filter)."""

    header: str
    cell: Callable[[Entry, set[str] | None], Cell]


def _text(get: Callable[[Entry], str]) -> Callable[[Entry, set[str] | None], Cell]:
    return lambda e, attacks: (get(e), None)


def _utility(name: str) -> Callable[[Entry, set[str] | None], Cell]:
    def cell(e: Entry, attacks: set[str] | None) -> Cell:
        stat = e.metric("utility", name)
        return pm(stat), None if stat is None else stat.mean
    return cell


def _worst(name: str, kind: str, digits: int, pct: bool = False, named: bool = True
           ) -> Callable[[Entry, set[str] | None], Cell]:
    def cell(e: Entry, attacks: set[str] | None) -> Cell:
        found = e.worst_case(name, kind, attacks)
        if found is None:
            return "", None
        stat, attack = found
        return (f"{pm(stat, digits, pct)}{_pooled_interval(e, name, attack, attacks)} "
                f"({attack}{_fewer_seeds(e, attack)})" if named else pm(stat, digits, pct)), stat.mean
    return cell


def _pooled_interval(e: Entry, name: str, attack: str, attacks: set[str] | None) -> str:
    """" [low, high]": a plate chain's Wilson 95 % interval on its plates pooled over seeds (from its
    per-plate units; "" without them or for another metric)."""
    if name != "plate_acc":
        return ""
    ensemble = plate_ensemble(e.rows, attacks)
    accuracy = None if ensemble is None else chain_accuracy(ensemble, attack)
    return "" if accuracy is None else f" [{100 * accuracy.interval[0]:.1f}, {100 * accuracy.interval[1]:.1f}]"


def _ensemble_plates(e: Entry, attacks: set[str] | None) -> Cell:
    """The ensemble's plate accuracy: mean ± seed sd [Wilson 95 % on the pooled plates] (chains)."""
    ensemble = plate_ensemble(e.rows, attacks)
    if ensemble is None:
        return ("no per-plate outcomes" if e.worst_case("plate_acc", "reader", attacks) else ""), None
    return f"{ensemble.accuracy.text()} ({len(ensemble.chains)} chains)", ensemble.accuracy.value


def _ensemble_psnr(e: Entry, attacks: set[str] | None) -> Cell:
    """Mean over scenes of each scene's best restorer: mean ± seed sd [scene bootstrap 95 %] (restorers)."""
    ensemble = scene_ensemble(e.rows, "psnr_db", attacks)
    if ensemble is None:
        return ("no per-scene outcomes" if e.worst_case("psnr_db", "restorer", attacks) else ""), None
    return f"{ensemble.text()} ({len(ensemble.restorers)} restorers)", ensemble.mean


def _fewer_seeds(e: Entry, attack: str) -> str:
    """", seed 0" when the chain ran on fewer seeds than its entry (e.g. a trained attacker fitted
    at seed 0 only), else ""."""
    chain = e.chain(attack)
    if chain is None or set(chain.seeds) >= set(e.seeds):
        return ""
    return f", seed{'s' if len(chain.seeds) > 1 else ''} {','.join(str(s) for s in chain.seeds)} only"


def _single(attack: str, name: str, fmt: str) -> Callable[[Entry, set[str] | None], Cell]:
    def cell(e: Entry, attacks: set[str] | None) -> Cell:
        stat = e.metric(attack, name)
        return ("", None) if stat is None else (format(stat.mean, fmt), stat.mean)
    return cell


def _bound_limited(e: Entry, attacks: set[str] | None) -> Cell:
    """"yes (seeds on a bound / seeds: terms)" when the trained mask ended on a coefficient bound in
    any seed, "no" when it never did, "" for a lens that was not trained (no such metric). A term on
    a bound in only some of those seeds says in how many ("Z3 tilt y in 1")."""
    chain = e.chain("lens")
    stat = None if chain is None else chain.metrics.get("bound_limited")
    if chain is None or stat is None:
        return "", None
    flags = [v for v in stat.values if v is not None]
    hit_rows = [r for r in chain.rows if (r.metric("bound_limited") or 0) > 0]
    if not hit_rows:
        return "no", 0.0
    counts: dict[str, int] = {}
    for row in hit_rows:
        for term in filter(None, (t.strip() for t in row.notes.get("bound_limited_terms", "").split(","))):
            counts[term] = counts.get(term, 0) + 1
    terms = ", ".join(t if n == len(hit_rows) else f"{t} in {n}" for t, n in counts.items())
    return f"yes ({len(hit_rows)}/{len(flags)} seeds{': ' + terms if terms else ''})", len(hit_rows) / len(flags)


ENSEMBLE_PLATES = "ensemble plate acc % [95 %] (any chain reads it)"
ENSEMBLE_PSNR = "ensemble PSNR dB [95 %] (per-scene best restorer)"

MAIN_COLUMNS = (
    Column("lens", _text(lambda e: e.lens)),
    Column("profile", _text(lambda e: e.profile)),
    Column("scenes", _text(lambda e: e.scenes)),
    Column("seeds", _text(lambda e: ",".join(map(str, e.seeds)))),
    Column("mIoU", _utility("miou")),
    Column("mA", _utility("mean_acc")),
    Column("OA", _utility("overall_acc")),
    Column(ENSEMBLE_PLATES, _ensemble_plates),
    Column("worst plate acc % (chain)", _worst("plate_acc", "reader", 1, pct=True)),
    Column(ENSEMBLE_PSNR, _ensemble_psnr),
    Column("worst PSNR dB (attacker)", _worst("psnr_db", "restorer", 2)),
    Column("worst SSIM", _worst("ssim", "restorer", 3, named=False)),
    Column("W_5% px (Fano, T=1)", _single("bound", "bound_width_eps_t1", ".0f")),
    Column("lens img/s", _single("lens", "images_per_s", ".1f")),
    Column("bound-limited", _bound_limited),
)
_FANO = next(i for i, c in enumerate(MAIN_COLUMNS) if c.header.startswith("W_5% px (Fano"))


def _observer(study: Mapping[str, Any] | None, frames: str, key: str, scale: float, fmt: str
              ) -> Callable[[Entry, set[str] | None], Cell]:
    def cell(e: Entry, attacks: set[str] | None) -> Cell:
        record = study_record(study, e.lens, e.lens_spec)
        value = None if record is None else record.get(frames, {}).get(key)
        return (NOT_COMPUTED, None) if value is None else (format(value * scale, fmt), float(value * scale))
    return cell


def observer_columns(study: Mapping[str, Any] | None) -> tuple[Column, ...]:
    """The ideal observer's plate ceiling at 32 px (T = 1) and its certified widths W_5% (T = 1, 30)."""
    return (Column("ceiling % at 32 px (ideal observer, T=1)", _observer(study, "t1", "plate_ceiling_w32", 100, ".1f")),
            Column("W_5% px (ideal observer, T=1)", _observer(study, "t1", "w5_plate_px", 1, ".0f")),
            Column("W_5% px (ideal observer, T=30)", _observer(study, "t30", "w5_plate_px", 1, ".0f")))


def gap_header(width_px: int) -> str:
    return f"attack gap pt at {width_px} px (ceiling - ensemble)"


def _gap(study: Mapping[str, Any] | None, width_px: int) -> Callable[[Entry, set[str] | None], Cell]:
    """The gap in the width bin starting at `width_px` ("gap [95 %]" in points), "not computed" where the
    study does not cover the lens (or has no ceiling there), "" where the entry has no such bin."""
    def cell(e: Entry, attacks: set[str] | None) -> Cell:
        gap = next((g for g in entry_gaps(e, study, attacks) if g.low_px == width_px), None)
        if gap is None:
            return ((NOT_COMPUTED if study_record(study, e.lens, e.lens_spec) is None else ""), None)
        return gap.text(), gap.gap
    return cell


def gap_columns(study: Mapping[str, Any] | None, entries: Sequence[Entry] = ()) -> tuple[Column, ...]:
    """The attack gap at GAP_WIDTHS_PX: 32 px always (every readable plate where widths are not
    recorded), 16 and 64 px only where some entry has plates binned by width there."""
    have = {g.low_px for e in entries for g in entry_gaps(e, study)}
    return tuple(Column(gap_header(w), _gap(study, w)) for w in GAP_WIDTHS_PX if w == 32 or w in have)


def table_columns(study: Mapping[str, Any] | None, entries: Sequence[Entry] = ()) -> tuple[Column, ...]:
    """MAIN_COLUMNS with the ideal observer's columns after the Fano bound's W_5%, then the attack gap's."""
    return (MAIN_COLUMNS[:_FANO + 1] + observer_columns(study) + gap_columns(study, entries)
            + MAIN_COLUMNS[_FANO + 1:])


def _markdown(head: Sequence[str], lines: Sequence[Sequence[str]]) -> str:
    """A Markdown table; cells hold names from plugins and entries, so each is made inert (md_cell)."""
    out = ["| " + " | ".join(head) + " |", "|" + "|".join(["---"] * len(head)) + "|"]
    return "\n".join(out + ["| " + " | ".join(md_cell(c) for c in cells) + " |" for cells in lines])


def main_table(entries: Sequence[Entry], study: Mapping[str, Any] | None = None) -> str:
    """Utility against the worst case of every attacker, one line per entry (markdown); `study`: the
    ideal-observer study (None: its columns read "not computed")."""
    columns = table_columns(study, entries)
    return _markdown([c.header for c in columns], [[c.cell(e, None)[0] for c in columns] for e in entries])


def contributions_table(entries: Sequence[Entry]) -> str:
    """Per entry, every chain of its plate ensemble: plates it read and plates only it read, as shares of
    the ensemble's reads pooled over seeds (markdown; chains that read nothing are left out)."""
    lines = []
    for e in entries:
        ensemble = plate_ensemble(e.rows)
        if ensemble is None:
            continue
        for c in ensemble.contributions:
            if c.read:
                lines.append([e.lens, e.profile, e.scenes, c.attack, ",".join(map(str, c.seeds)),
                              f"{c.read} / {c.of} ({100 * c.share:.1f} %)", f"{c.only} ({100 * c.only_share:.1f} %)"])
    return _markdown(["lens", "profile", "scenes", "chain", "seeds", "ensemble plates it read (share)",
                      "plates only it read (share)"], lines)


def ensemble_summary(entries: Sequence[Entry]) -> str:
    """One sentence per profile, generated from the entries: each lens's ensemble plate accuracy against
    its strongest single chain's (pooled over seeds, Wilson 95 %), where the two differ and where not."""
    out = []
    for profile in dict.fromkeys(e.profile for e in entries):
        parts = []
        for e in entries:
            ensemble = None if e.profile != profile else plate_ensemble(e.rows)
            found = None if ensemble is None else e.worst_case("plate_acc", "reader")
            single = None if found is None or ensemble is None else chain_accuracy(ensemble, found[1])
            if ensemble is None or found is None or single is None:
                continue
            a, s = ensemble.accuracy, single
            parts.append(f"{e.lens} {100 * a.value:.1f} % [{100 * a.interval[0]:.1f}, {100 * a.interval[1]:.1f}] "
                         f"against {100 * s.value:.1f} % [{100 * s.interval[0]:.1f}, {100 * s.interval[1]:.1f}] "
                         f"({found[1]})")
        if parts:
            out.append(f"Plates read by the ensemble of every chain against the strongest single chain "
                       f"({profile}, pooled over seeds, Wilson 95 %): " + "; ".join(parts) + ".")
    return "\n\n".join(out)


def flags_table(flags: Sequence[Flag]) -> str:
    """The attack flags (benchmark.results.attack_gap), markdown."""
    return _markdown(["lens", "profile", "flag", "what"], [[f.lens, f.profile, f.kind, f.message] for f in flags])


def violations_table(found: Sequence[tuple[Entry, Any]]) -> str:
    """The readers above their lens's ideal-observer ceiling (benchmark.results.observer.published), markdown."""
    return _markdown(["lens", "profile", "scenes", "reader", "plate acc %", "95 % interval", "plates",
                      "ceiling % (upper 95 %)"],
                     [[e.lens, e.profile, e.scenes, v.measured.reader, f"{100 * v.measured.accuracy:.1f}",
                       f"{100 * v.measured.interval[0]:.1f}-{100 * v.measured.interval[1]:.1f}",
                       str(v.measured.n_plates), f"{100 * v.ceiling_high:.1f}"] for e, v in found])


FINDINGS_HEAD = ("profile", "finding", "a", "b", "a's figure", "b's figure", "paired a - b [95 % CI]", "p", "test",
                 "n", "verdict")


def findings_lines(entries: Sequence[Entry]) -> list[list[str]]:
    """One line of cells (FINDINGS_HEAD) per finding checked on the entries (benchmark.publish.findings)."""
    return [[f.profile, f.claim + (" (suite check)" if f.source == "suite" else ""), f.lens_a, f.lens_b,
             f.figure_text("a"), f.figure_text("b"), f.difference_text(), f.p_text(),
             "" if f.comparison is None else f.comparison.method, "" if f.comparison is None else str(f.comparison.n),
             f.decision_text()] for f in check_findings(entries)]


def findings_table(entries: Sequence[Entry]) -> str:
    """The paper's findings decided per profile by paired comparisons (benchmark.publish.findings), or "" when
    none applies."""
    lines = findings_lines(entries)
    return _markdown(FINDINGS_HEAD, lines) if lines else ""


def attacker_table(entries: Sequence[Entry]) -> str:
    """Every attack chain of every entry with its own figures (markdown)."""
    lines = []
    for e in entries:
        for chain in e.chains():
            if chain.kind in ("lens", "utility", "bound"):
                continue
            m = chain.metrics.get
            fit, speed = m("fit_s"), m("images_per_s")
            lines.append([e.lens, chain.attack, ",".join(map(str, chain.seeds)), chain.threat_model or "",
                          pm(m("psnr_db"), 2), pm(m("ssim")), pm(m("plate_acc"), 1, pct=True), pm(m("plate_cer")),
                          f"{fit.mean:.1f}" if fit else "", f"{speed.mean:.2f}" if speed else ""])
    return _markdown(["lens", "attack", "seeds", "threat model", "PSNR dB", "SSIM", "plate acc %", "plate CER",
                      "fit s", "img/s"], lines)
