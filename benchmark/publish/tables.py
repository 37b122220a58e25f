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

from benchmark.publish.findings import Finding, check_findings
from benchmark.results.attack_gap import GAP_ALARM, GAP_WIDTHS_PX, Flag, ceiling_at, entry_gaps, pooled_bracket
from benchmark.results import pooled
from benchmark.results.ensemble import chain_accuracy, plate_ensemble, scene_ensemble
from benchmark.results.entries import Entry
from benchmark.results.markdown import md_cell
from benchmark.results.observer.published import NOT_COMPUTED, marginal_t1_curve, study_record

# A cell: its text and the number it sorts by (None: empty).
Cell = tuple[str, float | None]


CONVENTION = ("Every figure is pooled over the scenes or plates of all its seeds, x [low, high] being its pooled 95 % "
              "interval (plates: Wilson; scenes: bootstrap within seeds), and the seed spread (standard deviation of "
              "the per-seed figures, how much a re-trained lens or attacker moves) is its own column; a cell without "
              "per-unit outcomes says so instead of an interval.")


@dataclasses.dataclass(frozen=True)
class Column:
    """A trade-off table column: header, cell(entry, attacks) where `attacks` (None: all) limits the
    privacy figures to some attackers (the web page's threat-model filter), and what it shows (`tip`,
    the web page's tooltip and legend)."""

    header: str
    cell: Callable[[Entry, set[str] | None], Cell]
    tip: str = ""


def _text(get: Callable[[Entry], str]) -> Callable[[Entry, set[str] | None], Cell]:
    return lambda e, attacks: (get(e), None)


def _ci(found: pooled.Pooled | None, digits: int, scale: float = 1.0) -> Cell:
    """"value [pooled 95 %]", or "value (no per-unit outcomes)"; "" for no value."""
    return ("", None) if found is None else (found.text(digits, scale), found.value * scale)


def _spread(found: pooled.Pooled | None, digits: int, scale: float = 1.0) -> Cell:
    """The seed spread of a pooled figure ("" for one seed or no value)."""
    if found is None or found.n_seeds < 2:
        return "", None
    return found.spread_text(digits, scale), found.seed_std * scale


def _utility(name: str) -> Callable[[Entry, set[str] | None], Cell]:
    return lambda e, attacks: _ci(pooled.utility(e, name), 3)


def _miou_spread(e: Entry, attacks: set[str] | None) -> Cell:
    return _spread(pooled.miou(e), 3)


def _worst(name: str, kind: str, digits: int, pct: bool = False, named: bool = True
           ) -> Callable[[Entry, set[str] | None], Cell]:
    """The strongest single attacker's figure over its own units and seeds, pooled ("value [95 %] (attack)")."""
    def cell(e: Entry, attacks: set[str] | None) -> Cell:
        found = e.worst_case(name, kind, attacks)
        if found is None:
            return "", None
        attack = found[1]
        figure = pooled.plates(e, {attack}) if name == "plate_acc" else pooled.chain_metric(e, attack, name)
        text, value = _ci(figure, digits, 100.0 if pct else 1.0)
        return (f"{text} ({attack}{_fewer_seeds(e, attack)})" if named else text), value
    return cell


def _ensemble_plates(e: Entry, attacks: set[str] | None) -> Cell:
    """The ensemble's plate accuracy: pooled plates read / scored [Wilson 95 %] (chains)."""
    ensemble = plate_ensemble(e.rows, attacks)
    if ensemble is None:
        return ("no per-plate outcomes" if e.worst_case("plate_acc", "reader", attacks) else ""), None
    found = pooled.plates(e, attacks)
    assert found is not None
    return f"{found.text(1, 100.0)} ({len(ensemble.chains)} chains)", 100 * found.value


def _ensemble_plates_spread(e: Entry, attacks: set[str] | None) -> Cell:
    return _spread(pooled.plates(e, attacks) if plate_ensemble(e.rows, attacks) else None, 1, 100.0)


def _ensemble_psnr(e: Entry, attacks: set[str] | None) -> Cell:
    """Mean over scenes of each scene's best restorer: mean [scene bootstrap 95 %] (restorers)."""
    ensemble = scene_ensemble(e.rows, "psnr_db", attacks)
    if ensemble is None:
        return ("no per-scene outcomes" if e.worst_case("psnr_db", "restorer", attacks) else ""), None
    low, high = ensemble.interval
    return (f"{ensemble.mean:.2f} [{low:.2f}, {high:.2f}] ({len(ensemble.restorers)} restorers)",
            ensemble.mean)


def _ensemble_psnr_spread(e: Entry, attacks: set[str] | None) -> Cell:
    ensemble = scene_ensemble(e.rows, "psnr_db", attacks)
    if ensemble is None or len(ensemble.seed_values) < 2:
        return "", None
    return f"{ensemble.seed_std:.2f}", ensemble.seed_std


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
_PLATES_TIP = ("plates read by the ensemble (a plate counts as read when any reader chain of the suite read it "
               "exactly), % of the plates of every seed pooled, [Wilson 95 %]; lower = more private")
_MIOU_TIP = ("utility: mean intersection over union of the segmentation net on the sensor images, mean over seeds of "
             "each seed's mIoU pooled over its scenes, [scene bootstrap 95 %]; higher = more useful")
_SEEDS_TIP = "the seeds (independent lens and attacker trainings) the figures pool"

MAIN_COLUMNS = (
    Column("lens", _text(lambda e: e.lens), "the lens (python -m benchmark list describes each)"),
    Column("profile", _text(lambda e: e.profile), "the run profile: scene and network sizes, budgets"),
    Column("scenes", _text(lambda e: e.scenes), "the scene set"),
    Column("seeds", _text(lambda e: ",".join(map(str, e.seeds))), _SEEDS_TIP),
    Column("mIoU [95 %]", _utility("miou"), _MIOU_TIP),
    Column("mIoU seed sd", _miou_spread, "standard deviation of the per-seed mIoU (seed spread)"),
    Column("mA", _utility("mean_acc"), "mean class accuracy, mean over seeds (rows keep no per-scene outcomes of it)"),
    Column("OA", _utility("overall_acc"), "overall pixel accuracy, mean over seeds (rows keep no per-scene outcomes of "
                                          "it)"),
    Column(ENSEMBLE_PLATES, _ensemble_plates, _PLATES_TIP + "; (chains that joined)"),
    Column("ensemble plate acc seed sd pt", _ensemble_plates_spread,
           "standard deviation of the ensemble's per-seed plate accuracy, in points (seed spread)"),
    Column("worst plate acc % [95 %] (chain)", _worst("plate_acc", "reader", 1, pct=True),
           "the strongest single reader chain's own plate accuracy, its plates pooled over its seeds [Wilson 95 %]"),
    Column(ENSEMBLE_PSNR, _ensemble_psnr, "mean over scenes of each scene's best restorer's PSNR, mean over seeds "
                                          "[scene bootstrap 95 %]; (restorers that joined)"),
    Column("ensemble PSNR seed sd dB", _ensemble_psnr_spread,
           "standard deviation of the ensemble's per-seed PSNR (seed spread)"),
    Column("worst PSNR dB [95 %] (attacker)", _worst("psnr_db", "restorer", 2),
           "the strongest single restorer's PSNR over its scenes and seeds [scene bootstrap 95 %]"),
    Column("worst SSIM [95 %]", _worst("ssim", "restorer", 3, named=False),
           "the strongest single restorer's SSIM over its scenes and seeds [scene bootstrap 95 %]"),
    Column("W_5% px (Fano, T=1)", _single("bound", "bound_width_eps_t1", ".0f"),
           "the plate width below which the Gaussian information bound (Fano) certifies that no attacker reads "
           "more than 5 % of plates from one frame (a deterministic bound: no interval)"),
    Column("lens img/s", _single("lens", "images_per_s", ".1f"), "images the lens simulation renders per second, "
                                                                   "mean over seeds (a speed: no interval)"),
    Column("bound-limited", _bound_limited, "whether a trained mask ended on a coefficient bound, in how many seeds "
                                            "and which terms"),
)
_FANO = next(i for i, c in enumerate(MAIN_COLUMNS) if c.header.startswith("W_5% px (Fano"))


def _observer(study: Mapping[str, Any] | None, frames: str, key: str, scale: float, fmt: str
              ) -> Callable[[Entry, set[str] | None], Cell]:
    def cell(e: Entry, attacks: set[str] | None) -> Cell:
        record = study_record(study, e.lens, e.lens_spec)
        value = None if record is None else record.get(frames, {}).get(key)
        return (NOT_COMPUTED, None) if value is None else (format(value * scale, fmt), float(value * scale))
    return cell


def _tighter(study: Mapping[str, Any] | None, width_px: int) -> Callable[[Entry, set[str] | None], Cell]:
    """The tighter (marginalised) T = 1 plate ceiling in the bin holding `width_px`, % [95 %]."""
    def cell(e: Entry, attacks: set[str] | None) -> Cell:
        curve = marginal_t1_curve(study_record(study, e.lens, e.lens_spec))
        found = None if curve is None else ceiling_at(curve, width_px)
        if found is None:
            return NOT_COMPUTED, None
        value, (low, high) = found
        return f"{100 * value:.1f} [{100 * low:.1f}, {100 * high:.1f}]", 100 * value
    return cell


def observer_columns(study: Mapping[str, Any] | None) -> tuple[Column, ...]:
    """The ideal observer's plate ceiling at 32 px (T = 1; the genie's, then the tighter one's) and its
    certified widths W_5% (T = 1, 30)."""
    where = "; \"not computed\" where the study did not use the entry's own lens spec"
    return (Column("ceiling % at 32 px (ideal observer, T=1)", _observer(study, "t1", "plate_ceiling_w32", 100, ".1f"),
                   "the most any attacker can read of 32 px plates from one frame (the Bayesian ideal observer)" + where),
            Column("tighter ceiling % [95 %] at 32-48 px (T=1)", _tighter(study, 32),
                   "the same for an ideal observer not told the plate's exact position and width (averaged over the "
                   "bin's widths): the most an attacker that must find the plate could read; \"not computed\" "
                   "where the study has no marginalised curve for the entry's lens spec"),
            Column("W_5% px (ideal observer, T=1)", _observer(study, "t1", "w5_plate_px", 1, ".0f"),
                   "the widest plate the ideal observer reads at most 5 % of, one frame" + where),
            Column("W_5% px (ideal observer, T=30)", _observer(study, "t30", "w5_plate_px", 1, ".0f"),
                   "the same from 30 frames" + where))


def gap_header(width_px: int) -> str:
    return f"attack gap pt at {width_px} px (ceiling - ensemble)"


def gap_tip(width_px: int) -> str:
    return (f"the ideal observer's plate ceiling at {width_px} px minus the ensemble's plate accuracy there, in points "
            "[95 %: the ceiling's Monte-Carlo interval against the ensemble's Wilson interval]; large = the suite's "
            "attackers are far from the best possible reader, so privacy is overstated; \"not computed\" where the "
            "ideal-observer study did not use the entry's own lens spec")


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
    return tuple(Column(gap_header(w), _gap(study, w), gap_tip(w)) for w in GAP_WIDTHS_PX if w == 32 or w in have)


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


def _finding_figure(entries: Sequence[Entry], f: Finding, side: str) -> str:
    """A finding's figure of one side as the trade-off table shows it: pooled, "value [95 %] (attack)";
    the finding's own text where the entry is not unique in its profile (several scene sets)."""
    lens, attack = (f.lens_a, f.attack_a) if side == "a" else (f.lens_b, f.attack_b)
    mine = [e for e in entries if e.lens == lens and e.profile == f.profile]
    if len(mine) != 1 or attack is None or f.measure not in ("miou", "psnr_db", "plate_acc"):
        return f.figure_text(side)
    e = mine[0]
    if f.measure == "miou":
        return _ci(pooled.miou(e), 3)[0]
    found = pooled.chain_metric(e, attack, "psnr_db") if f.measure == "psnr_db" else pooled.chain_plates(e, attack)
    text = _ci(found, 2 if f.measure == "psnr_db" else 1, 1.0 if f.measure == "psnr_db" else 100.0)[0]
    return f"{text} ({attack})" if text else f.figure_text(side)


def findings_lines(entries: Sequence[Entry]) -> list[list[str]]:
    """One line of cells (FINDINGS_HEAD) per finding checked on the entries (benchmark.publish.findings)."""
    return [[f.profile, f.claim + (" (suite check)" if f.source == "suite" else ""), f.lens_a, f.lens_b,
             _finding_figure(entries, f, "a"), _finding_figure(entries, f, "b"), f.difference_text(), f.p_text(),
             "" if f.comparison is None else f.comparison.method, "" if f.comparison is None else str(f.comparison.n),
             f.decision_text()] for f in check_findings(entries)]


def findings_table(entries: Sequence[Entry]) -> str:
    """The paper's findings decided per profile by paired comparisons (benchmark.publish.findings), or "" when
    none applies."""
    lines = findings_lines(entries)
    return _markdown(FINDINGS_HEAD, lines) if lines else ""


ATTACKER_HEAD = ("lens", "attack", "seeds", "threat model", "PSNR dB [95 %]", "SSIM [95 %]", "plate acc % [95 %]",
                 "seed sd (PSNR dB or plate acc pt)", "plate CER", "fit s", "img/s")


def attacker_table(entries: Sequence[Entry]) -> str:
    """Every attack chain of every entry with its own figures, each pooled over its units and seeds with
    its 95 % interval, the seed spread of its main figure (PSNR, else plate accuracy) apart (markdown)."""
    lines = []
    for e in entries:
        for chain in e.chains():
            if chain.kind in ("lens", "utility", "bound"):
                continue
            m = chain.metrics.get
            psnr, plates = pooled.chain_metric(e, chain.attack, "psnr_db"), pooled.chain_plates(e, chain.attack)
            spread = _spread(psnr, 2) if psnr is not None else _spread(plates, 1, 100.0)
            fit, speed, cer = m("fit_s"), m("images_per_s"), m("plate_cer")
            lines.append([e.lens, chain.attack, ",".join(map(str, chain.seeds)), chain.threat_model or "",
                          _ci(psnr, 2)[0], _ci(pooled.chain_metric(e, chain.attack, "ssim"), 3)[0],
                          _ci(plates, 1, 100.0)[0], spread[0],
                          f"{cer.mean:.3f} (no per-plate CER)" if cer else "",
                          f"{fit.mean:.1f}" if fit else "", f"{speed.mean:.2f}" if speed else ""])
    return _markdown(list(ATTACKER_HEAD), lines)


# The privacy level of the takeaway: a lens counts as private when the upper 95 % limit of the plates its
# ensemble reads is below it.
PRIVATE_LEVEL = 0.05
REFERENCE = "sharp"  # the no-lens reference entry: on the Pareto front, never "the lens that keeps most utility"


def _headline_plates(e: Entry, attacks: set[str] | None) -> Cell:
    if plate_ensemble(e.rows, attacks) is None:
        return ("no per-plate outcomes" if e.worst_case("plate_acc", "reader", attacks) else ""), None
    return _ci(pooled.plates(e, attacks), 1, 100.0)


def headline_columns(study: Mapping[str, Any] | None) -> tuple[Column, ...]:
    """The web page's first table: lens, utility, the ensemble's privacy, the ceiling gap and the seeds."""
    return (Column("lens", _text(lambda e: e.lens), "the lens (python -m benchmark list describes each)"),
            Column("mIoU [95 %]", _utility("miou"), _MIOU_TIP),
            Column("plates read % [95 %]", _headline_plates, _PLATES_TIP),
            Column("ceiling gap pt [95 %]", _gap(study, 32), gap_tip(32)),
            Column("seeds", _text(lambda e: ",".join(map(str, e.seeds))), _SEEDS_TIP))


def _measured_on(e: Entry, attacks: set[str] | None) -> Cell:
    dates = sorted(str(r.provenance.get("date", ""))[:10] for r in e.rows if r.provenance.get("date"))
    return (dates[-1] if dates else "not recorded"), None


def readme_columns(study: Mapping[str, Any] | None) -> tuple[Column, ...]:
    """The project README's short table: the headline columns, the ensemble's PSNR and when the entry was
    measured (its newest row's date: entries of other dates may be of another version)."""
    lens, miou, plates, gap, seeds = headline_columns(study)
    return (lens, miou, plates, Column("ensemble PSNR dB [95 %]", _ensemble_psnr, "per scene, its best restorer"),
            gap, seeds, Column("measured", _measured_on, "the date of the entry's newest row"))


def readme_table(entries: Sequence[Entry], study: Mapping[str, Any] | None = None, profile: str = "quick") -> str:
    """The project README's results table (markdown): `readme_columns`, one line per entry of `profile`."""
    columns = readme_columns(study)
    return _markdown([c.header for c in columns],
                     [[c.cell(e, None)[0] for c in columns] for e in entries if e.profile == profile])


def bracket_lines(entries: Sequence[Entry], study: Mapping[str, Any] | None) -> list[str]:
    """One sentence per entry the study covers: its privacy lies between what the ensemble reads of its readable
    plates (the tables' figure) and what the ideal observer reads of the same plates (``attack_gap.pooled_bracket``,
    the tighter ceiling where the study has it), the verdict the gap's interval's."""
    lines = []
    for e in entries:
        bracket = pooled_bracket(e, study)
        if bracket is None:
            continue
        a = bracket.ensemble
        which = {"marginal": "the tighter ceiling: an ideal observer that must find the plate",
                 "genie": "the genie ceiling: an ideal observer told where the plate is"}.get(
            bracket.ceiling_kind, "the tighter ceiling where the study tabulates the plate's width, else the genie's")
        low, high = bracket.interval
        points = f"{100 * GAP_ALARM:.0f} points"
        verdict = (f"the attackers are more than {points} below it: the suite overstates this lens's privacy"
                   if low > GAP_ALARM else f"the attackers are within {points} of it" if high < GAP_ALARM else
                   f"cannot tell whether the attackers are within {points} of it (too few plates)")
        lines.append(f"- **{e.lens}** ({e.profile}, plates from {bracket.from_px:g} px): between {100 * a.value:.1f} % "
                     f"{_pct(a.interval)} read by the ensemble and {100 * bracket.ceiling:.1f} % "
                     f"{_pct(bracket.ceiling_interval)} read by the ideal observer ({which}); {verdict}.")
    return lines


def _pct(interval: tuple[float, float]) -> str:
    return f"[{100 * interval[0]:.1f}, {100 * interval[1]:.1f}]"


def takeaways(entries: Sequence[Entry], study: Mapping[str, Any] | None = None) -> dict[str, str]:
    """Per profile, one sentence generated from its entries answering "which lens keeps most utility for how
    much privacy": the lens with the highest mIoU among those whose ensemble reads under PRIVATE_LEVEL of
    plates at the upper 95 % limit (or, with none, the highest mIoU overall), the Pareto front on mIoU
    against ensemble plate accuracy (pooled), and how many lenses' ceiling gap is over GAP_ALARM."""
    from benchmark.results.attack_gap import GAP_ALARM
    from benchmark.results.charts.tradeoff import pareto_front

    out = {}
    for profile in dict.fromkeys(e.profile for e in entries):
        scored = []
        for e in entries:
            if e.profile != profile or plate_ensemble(e.rows) is None:
                continue
            utility, plates = pooled.miou(e), pooled.plates(e)
            if utility is not None and plates is not None and plates.interval is not None:
                scored.append((e, utility, plates))
        if not scored:
            out[profile] = ("No entry of this profile carries per-plate outcomes with its plate accuracy, so no "
                            "lens can be said to keep most utility for its privacy.")
            continue
        private = [x for x in scored if x[2].interval[1] < PRIVATE_LEVEL]  # type: ignore[index]
        lenses = [x for x in scored if x[0].lens != REFERENCE] or scored  # the sharp reference is no lens
        level = f"{100 * PRIVATE_LEVEL:g} %"
        if private:
            e, u, p = max(private, key=lambda x: x[1].value)
            head = (f"of the {len(private)} of {len(lenses)} lenses whose ensemble reads under {level} of plates "
                    f"(upper 95 % limit), {e.lens} keeps the most utility: mIoU {u.text(3)}, plates read "
                    f"{100 * p.value:.1f} % {_pct(p.interval)}")  # type: ignore[arg-type]
        else:
            e, u, p = max(lenses, key=lambda x: x[1].value)
            f = min(lenses, key=lambda x: x[2].value)
            why = ": too few plates to tell" if f[2].value < PRIVATE_LEVEL else ""
            head = (f"none of the {len(lenses)} lenses is shown to read under {level} of plates (the fewest read: "
                    f"{f[0].lens}, {100 * f[2].value:.1f} % {_pct(f[2].interval)}{why}); the most utility: "  # type: ignore[arg-type]
                    f"{e.lens}, mIoU {u.text(3)}, plates read {100 * p.value:.1f} % {_pct(p.interval)}")  # type: ignore[arg-type]
        front = [scored[i] for i in pareto_front([(x[2].value, x[1].value) for x in scored])]
        head += ("; Pareto front (each lens more private than the next, the next more useful): "
                 + ", ".join(f"{x[0].lens} ({x[1].value:.3f}, {100 * x[2].value:.1f} %)" for x in front))
        gaps = [g for x in scored for g in entry_gaps(x[0], study) if g.low_px == 32]
        if gaps:
            over = sum(g.gap > GAP_ALARM for g in gaps)
            head += (f"; the ceiling gap is over {100 * GAP_ALARM:.0f} points for {over} of the {len(gaps)} lenses the "
                     "ideal-observer study covers" + (": the suite's attackers read far fewer plates than the best "
                                                      "possible reader, so privacy is overstated"
                                                      if over else ""))
        out[profile] = head[0].upper() + head[1:] + "."
    return out
