"""The attack gap (the ideal observer's ceiling minus the ensemble's plate accuracy) and the flags that
say when a lens's privacy figure should not be trusted, in the spirit of AutoAttack's checks.

Gap. Per lens and plate-width bin: the T = 1 plate ceiling (``leaderboard/studies/ideal_observer.json``,
only where the study used the lens's own spec: ``benchmark.results.observer.published.study_record``)
minus the ensemble's accuracy in the bin (``benchmark.results.ensemble``). The ceiling is the tighter,
marginalised one (``observer.marginal``: the ideal observer not told the plate's position, scale and
exposure) where the study holds it, its value for the bin that starts at the bin's lower edge (the
bin's average over the width prior); else (and in bins the tighter curve does not tabulate) the
genie's at the bin's lower edge (it rises with width,
so that is the least over the bin and the gap a lower bound on the bin's mean gap). ``Gap.ceiling_kind``
says which. Plate units without recorded widths give one bin, every readable
plate (>= LEGACY_READABLE_MIN_WIDTH_PX): the gap "at 32 px". Its 95 % interval combines the ceiling's
Monte-Carlo interval and the ensemble's Wilson interval (low = ceiling low - ensemble high).

Pooled bracket (``pooled_bracket``): the same figure as the leaderboard's pooled plate accuracy (the
ensemble's reads of every readable plate of every seed) against what the ideal observer reads of those
same plates: the mean over them of the ceiling at each plate's width (the tighter curve where it
tabulates the width, else the genie's; a plate wider than every tabulated width counts at the widest,
a lower bound since the ceiling rises with width). Its interval is the mean of the per-width 95 % limits.

Flags (``Flag.kind``):

- ``above-ceiling``: a reader or chain reads more than the genie's ceiling allows (its Wilson interval
  above the ceiling's upper limit, ``observer.consistency``): a modelling or scoring error.
- ``above-tighter-ceiling``: above the marginalised ceiling but not the genie's: the reader knows what
  the nuisance prior says no attacker knows, or the scenes' nuisances are narrower than the prior.
- ``fit-still-rising``: a learned attacker's row carries the note ``fit_still_rising`` = "true"
  (``schema.FIT_STILL_RISING``): its fit stopped while held-out accuracy was still improving, so it
  is a lower bound on what that attacker reaches.
- ``untrained-beats-trained``: an attacker that learns nothing beats, by a paired test at the 5 % level,
  one that learns: the learning one is under-fitted. Rows that carry the note ``learns``
  (``Attack.learns``) are compared across families: every learning restorer with every restorer that
  learns nothing of an equal or weaker threat model (e.g. wiener-known-psf against nafnet-known-psf,
  demosaic-vng against every learning one), and chains likewise when they share their reader. Rows
  without the note (entries measured before it) keep the older rule: sensor-access attackers count as
  not learning the lens, compared only within their family (same name before the first "-", e.g.
  nafnet-generic and nafnet-known-pairs; a chain's family is its restorer's with the same reader).
- ``attack-gap``: a gap over ``GAP_ALARM`` (30 points) in a bin where the ceiling (the tighter one where
  the study holds it) exceeds ``CEILING_ALARM`` (50 %): the suite's attackers are weak here, privacy is
  overstated.
"""

from __future__ import annotations

import dataclasses
import math
from collections.abc import Iterable, Mapping, Sequence
from typing import Any

import numpy as np

from benchmark.results import stats
from benchmark.results.ensemble import Accuracy, PlateEnsemble, plate_ensemble, pooled_min_width, seed_scenes
from benchmark.results.entries import Entry
from benchmark.results.observer.ceiling import CeilingCurve
from benchmark.results.observer.consistency import BinAccuracy, check_consistency
from benchmark.results.observer.published import marginal_t1_curve, study_record, t1_curve
from benchmark.results.schema import FIT_STILL_RISING, LEARNS, Row, threat_models

__all__ = ["CEILING_ALARM", "FLAG_KINDS", "GAP_ALARM", "GAP_WIDTHS_PX", "Bracket", "Flag", "Gap", "attack_gaps",
           "entry_flags", "entry_gaps", "gap_curves", "lens_flags", "pooled_bracket"]

GAP_ALARM = 0.30
CEILING_ALARM = 0.50
# Widths whose gap the leaderboard shows (a bin starting there, where the entry has one).
GAP_WIDTHS_PX = (16, 32, 64)
FLAG_KINDS = ("above-ceiling", "above-tighter-ceiling", "fit-still-rising", "untrained-beats-trained", "attack-gap")
UNTRAINED = "sensor-access"
_TRUE, _FALSE = ("true", "1", "yes"), ("false", "0", "no")


@dataclasses.dataclass(frozen=True)
class Gap:
    """Ceiling minus ensemble accuracy on plates of width [low_px, high_px) (see the module docstring).

    pooled: True when the plates carry no widths and the bin is every readable plate; ceiling_kind:
    "marginal" (the tighter ceiling) or "genie".
    """

    low_px: float
    high_px: float
    ceiling: float
    ceiling_interval: tuple[float, float]
    ensemble: Accuracy
    pooled: bool
    ceiling_kind: str = "genie"

    @property
    def gap(self) -> float:
        return self.ceiling - self.ensemble.value

    @property
    def interval(self) -> tuple[float, float]:
        return self.ceiling_interval[0] - self.ensemble.interval[1], self.ceiling_interval[1] - self.ensemble.interval[0]

    def where(self) -> str:
        """"32 px" for a pooled bin (all readable plates, from 32 px), else "32-48 px" / ">= 192 px"."""
        if self.pooled:
            return f"{self.low_px:g} px (every readable plate >= {self.low_px:g} px)"
        return f">= {self.low_px:g} px" if math.isinf(self.high_px) else f"{self.low_px:g}-{self.high_px:g} px"

    def text(self) -> str:
        """"gap [low, high]" in points."""
        return f"{100 * self.gap:.1f} [{100 * self.interval[0]:.1f}, {100 * self.interval[1]:.1f}]"


@dataclasses.dataclass(frozen=True)
class Flag:
    """One warning on a lens's privacy figure (``kind`` one of FLAG_KINDS)."""

    lens: str
    profile: str
    kind: str
    message: str

    def __post_init__(self) -> None:
        if self.kind not in FLAG_KINDS:
            raise ValueError(f"Flag.kind {self.kind!r} is not one of {FLAG_KINDS}")

    def text(self) -> str:
        return f"{self.lens} ({self.profile}): {self.kind}: {self.message}"


def ceiling_at(curve: CeilingCurve, width_px: float) -> tuple[float, tuple[float, float]] | None:
    """The T = 1 plate ceiling and its 95 % interval at `width_px` (linear between tabulated widths; a
    marginalised curve: the value of the bin [w_k, high_k) holding `width_px`); None outside the tabulated
    widths (or bins)."""
    widths = curve.widths_px.astype(float)
    if curve.width_high_px is not None:
        inside = np.flatnonzero((widths <= width_px) & (width_px < curve.width_high_px))
        if not len(inside):
            return None
        k = int(inside[-1])
        value = float(curve.plate_ceiling[k])
        return value, (min(float(curve.plate_interval[k, 0]), value), max(float(curve.plate_interval[k, 1]), value))
    if not widths[0] <= width_px <= widths[-1]:
        return None
    value = float(np.interp(width_px, widths, curve.plate_ceiling))
    low = float(np.interp(width_px, widths, curve.plate_interval[:, 0]))
    high = float(np.interp(width_px, widths, curve.plate_interval[:, 1]))
    return value, (min(low, value), max(high, value))


def attack_gaps(ensemble: PlateEnsemble, curve: CeilingCurve, fallback: CeilingCurve | None = None) -> list[Gap]:
    """The gap per width bin of the ensemble (one pooled bin from its smallest pooled width where its
    plates carry no widths), for bins whose lower edge the curve tabulates, else (given) `fallback`
    tabulates (the genie's curve beside a tighter one computed on fewer widths)."""
    if ensemble.bins is None:
        bins: list[tuple[float, float, Accuracy, bool]] = [
            (ensemble.min_width_px(), math.inf, ensemble.accuracy, True)]
    else:
        bins = [(b.low_px, b.high_px, b.accuracy, False) for b in ensemble.bins]
    out = []
    for low, high, accuracy, pooled in bins:
        used = curve
        found = ceiling_at(curve, low)
        if found is None and fallback is not None:
            used, found = fallback, ceiling_at(fallback, low)
        if found is not None and accuracy.n:
            out.append(Gap(low, high, found[0], found[1], accuracy, pooled, used.kind))
    return out


def _curve(study: Mapping[str, Any] | None, lens: str, spec: Mapping[str, Any] | None) -> CeilingCurve | None:
    """The genie's T = 1 curve of the lens (None: the study does not cover its spec)."""
    return t1_curve(study_record(study, lens, spec))


def gap_curves(study: Mapping[str, Any] | None, lens: str, spec: Mapping[str, Any] | None
               ) -> tuple[CeilingCurve | None, CeilingCurve | None]:
    """(curve, fallback) the gap is taken against: the tighter (marginalised) T = 1 curve where the
    study's record of the lens holds one, with the genie's for the bins it does not tabulate; else the
    genie's alone; (None, None) where the study does not cover the lens's spec."""
    record = study_record(study, lens, spec)
    genie, tighter = t1_curve(record), marginal_t1_curve(record)
    return (genie, None) if tighter is None else (tighter, genie)


@dataclasses.dataclass(frozen=True)
class Bracket:
    """An entry's pooled privacy between what its ensemble reads and what the ideal observer reads of the
    same readable plates (see the module docstring); ``ceiling_kind``: "marginal" when the tighter curve
    gave every plate's ceiling, "genie" when it gave none, "mixed" otherwise; ``from_px``: the width the
    pooled figure starts at."""

    ensemble: Accuracy
    ceiling: float
    ceiling_interval: tuple[float, float]
    ceiling_kind: str
    from_px: float

    @property
    def interval(self) -> tuple[float, float]:
        """The gap's 95 % interval, as ``Gap.interval``: ceiling low - ensemble high, ceiling high - ensemble low."""
        return self.ceiling_interval[0] - self.ensemble.interval[1], self.ceiling_interval[1] - self.ensemble.interval[0]


def _ceiling_of_width(width_px: float, curve: CeilingCurve, fallback: CeilingCurve | None
                      ) -> tuple[float, tuple[float, float], str] | None:
    """The ceiling at `width_px` from `curve` where it tabulates the width, else from `fallback`; a width beyond
    both counts at the widest width either tabulates (module docstring)."""
    used = [c for c in (curve, fallback) if c is not None]
    for c in used:
        found = ceiling_at(c, width_px)
        if found is not None:
            return found[0], found[1], c.kind
    widest = max(used, key=lambda c: float(c.widths_px.max()))
    top = float(widest.widths_px.max())
    found = ceiling_at(widest, top) if width_px > top else None
    return None if found is None else (found[0], found[1], widest.kind)


def pooled_bracket(entry: Entry, study: Mapping[str, Any] | None, attacks: set[str] | None = None
                   ) -> Bracket | None:
    """The entry's pooled bracket (module docstring); None where the study does not cover its lens spec,
    its plates record no widths, or a plate's width lies below every tabulated one."""
    curve, fallback = gap_curves(study, entry.lens, entry.lens_spec)
    ensemble = None if curve is None else plate_ensemble(entry.rows, attacks)
    if curve is None or ensemble is None or any(p.widths is None for p in ensemble.per_seed):
        return None
    found = [_ceiling_of_width(float(w), curve, fallback) for p in ensemble.per_seed for w in p.widths]  # type: ignore[union-attr]
    if not found or any(f is None for f in found):
        return None
    kinds = {f[2] for f in found}  # type: ignore[index]
    return Bracket(ensemble.accuracy, float(np.mean([f[0] for f in found])),  # type: ignore[index]
                   (float(np.mean([f[1][0] for f in found])), float(np.mean([f[1][1] for f in found]))),  # type: ignore[index]
                   kinds.pop() if len(kinds) == 1 else "mixed", ensemble.min_width_px())


def entry_gaps(entry: Entry, study: Mapping[str, Any] | None, attacks: set[str] | None = None) -> list[Gap]:
    """The entry's gaps (none where the study does not cover its lens spec or no chain has plate units)."""
    curve, fallback = gap_curves(study, entry.lens, entry.lens_spec)
    ensemble = None if curve is None else plate_ensemble(entry.rows, attacks)
    return [] if curve is None or ensemble is None else attack_gaps(ensemble, curve, fallback)


def _family(name: str) -> str:
    return name.split("-", 1)[0]


def _rising(row: Row) -> bool:
    value = row.notes.get(FIT_STILL_RISING)
    if value is None:
        return False
    text = value.strip().lower()
    if text not in _TRUE + _FALSE:
        raise ValueError(f"row {row.lens}/{row.attack} seed {row.seed}: note {FIT_STILL_RISING!r} is {value!r}; "
                         f"write one of {_TRUE + _FALSE}")
    return text in _TRUE


def _row_accuracies(lens: str, rows: Sequence[Row]) -> list[BinAccuracy]:
    """Each reader and chain pooled over its seeds on every readable plate (as the entry check does)."""
    low = pooled_min_width(rows)
    counts: dict[str, list[int]] = {}
    for row in rows:
        acc, n = row.metrics.get("plate_acc"), row.metrics.get("n_plates")
        if row.ok and row.kind in ("reader", "chain") and acc is not None and n:
            tally = counts.setdefault(row.attack, [0, 0])
            tally[0] += round(acc * n)
            tally[1] += int(n)
    return [BinAccuracy(attack, lens, low, math.inf, hits / n, stats.wilson_interval(hits, n), n)
            for attack, (hits, n) in counts.items() if n]


def _learns(row: Row, threats: Mapping[str, str | None]) -> bool | None:
    """Whether the row's attacker learns: its ``learns`` note, else (older rows) not sensor-access; None
    for a reference row or one without a threat model."""
    if row.kind == "reference" or threats.get(row.attack) is None:
        return None
    note = row.notes.get(LEARNS)
    if note is not None:
        return note.strip().lower() in _TRUE
    return threats[row.attack] != UNTRAINED


def _comparable(weak: Row, strong: Row, threats: Mapping[str, str | None]) -> bool:
    """Whether a non-learning ``weak`` row is held against the learning ``strong`` one (module docs)."""
    reader = (weak.reader if weak.kind == "chain" else None) == (strong.reader if strong.kind == "chain" else None)
    if LEARNS in weak.notes and LEARNS in strong.notes:
        from attacks import ThreatModel  # lazy: reading rows needs no torch

        order = [t.value for t in ThreatModel]
        return reader and order.index(threats[weak.attack]) <= order.index(threats[strong.attack])
    return reader and _family(weak.restorer or weak.attack) == _family(strong.restorer or strong.attack)


def _stronger_untrained(rows: Sequence[Row]) -> list[str]:
    """Messages for every (non-learning, learning) pair held against each other (module docs) where the
    non-learning one is better by a paired test at the 5 % level: restorers by per-scene PSNR (stratified
    paired bootstrap), readers and chains by per-plate reads (McNemar)."""
    threats = threat_models(rows)
    ok = [r for r in rows if r.ok and r.units is not None]
    messages = []
    for kind, unit, value in (("restorer", "scene", "psnr_db"), ("plates", "plate", "correct")):
        kinds = ("restorer",) if kind == "restorer" else ("reader", "chain")
        attacks = list(dict.fromkeys(r.attack for r in ok if r.kind in kinds and r.units.unit == unit  # type: ignore[union-attr]
                                     and value in r.units.values))  # type: ignore[union-attr]
        first = {a: next(r for r in ok if r.attack == a) for a in attacks}
        for weak in attacks:
            if _learns(first[weak], threats) is not False:
                continue
            for strong in attacks:
                if strong == weak or not _learns(first[strong], threats) or not _comparable(first[weak], first[strong], threats):
                    continue
                comparison = (_restorer_comparison(ok, weak, strong) if kind == "restorer"
                              else _reader_comparison(ok, weak, strong))
                if comparison is None:
                    continue
                decided = stats.verdict(comparison, "greater")
                if decided.label == stats.HOLDS:
                    what = "PSNR dB" if kind == "restorer" else "plate accuracy"
                    scale, unit_text = (1.0, " dB") if kind == "restorer" else (100.0, " pt")
                    messages.append(
                        f"{weak} ({threats[weak]}, learns nothing) beats {strong} ({threats[strong]}, learns) on {what} by "
                        f"{scale * comparison.difference:+.2f}{unit_text} [{scale * comparison.low:+.2f}, "
                        f"{scale * comparison.high:+.2f}] ({decided.text.split(': ', 1)[1]}): {strong} is under-fitted")
    return messages


def _restorer_comparison(rows: Sequence[Row], a: str, b: str) -> stats.Comparison | None:
    sa, sb = [], []
    for seed in sorted({r.seed for r in rows}):
        found = seed_scenes(rows, seed, "psnr_db", {a, b})
        if found is None or set(found[0]) != {a, b}:
            continue
        names, values = found
        sa.append(values[:, names.index(a)])
        sb.append(values[:, names.index(b)])
    if not sa:
        return None
    return stats.stratified_paired_bootstrap(sa, sb, lambda s: float(np.mean([x.mean() for x in s])), n_resamples=2000)


def _reader_comparison(rows: Sequence[Row], a: str, b: str) -> stats.Comparison | None:
    ensemble = plate_ensemble(rows, {a, b})
    if ensemble is None:
        return None
    cells = np.zeros(4, dtype=int)
    for p in ensemble.per_seed:
        if set(p.chains) != {a, b} or not p.names:
            continue
        ra, rb = p.read[p.chains.index(a)], p.read[p.chains.index(b)]
        cells += stats.paired_table(ra, rb)
    return None if cells.sum() == 0 else stats.paired_accuracy_difference(*(int(c) for c in cells))


def lens_flags(lens: str, profile: str, rows: Iterable[Row], spec: Mapping[str, Any] | None,
               study: Mapping[str, Any] | None) -> list[Flag]:
    """Every flag of one lens's rows (a run's or an entry's), in FLAG_KINDS order; `spec` is the lens
    spec the study must match for the ceiling flags."""
    rows = [r for r in rows if r.lens == lens]
    curve = _curve(study, lens, spec)
    tighter = marginal_t1_curve(study_record(study, lens, spec))
    flags = []
    if curve is not None:
        accuracies = _row_accuracies(lens, rows)
        above = check_consistency(accuracies, {lens: curve})
        flags += [Flag(lens, profile, "above-ceiling", v.message()) for v in above]
        crossed = {v.measured.reader for v in above}
        if tighter is not None:
            flags += [Flag(lens, profile, "above-tighter-ceiling", v.message())
                      for v in check_consistency(accuracies, {lens: tighter}) if v.measured.reader not in crossed]
    rising: dict[str, list[int]] = {}
    for row in rows:
        if row.ok and _rising(row):
            rising.setdefault(row.attack, []).append(row.seed)
    for attack, seeds in rising.items():
        flags.append(Flag(lens, profile, "fit-still-rising",
                          f"{attack}'s fit was still improving when it stopped (seed{'s' if len(seeds) > 1 else ''} "
                          f"{','.join(map(str, sorted(seeds)))}): its figures are a lower bound on that attacker"))
    flags += [Flag(lens, profile, "untrained-beats-trained", m) for m in _stronger_untrained(rows)]
    against, fallback = (curve, None) if tighter is None else (tighter, curve)
    ensemble = None if against is None else plate_ensemble(rows)
    for gap in [] if ensemble is None or against is None else attack_gaps(ensemble, against, fallback):
        if gap.ceiling > CEILING_ALARM and gap.gap > GAP_ALARM:
            which = "tighter (marginalised) ceiling" if gap.ceiling_kind == "marginal" else "ceiling (genie)"
            flags.append(Flag(lens, profile, "attack-gap",
                              f"the ensemble reads {gap.ensemble.text()} % of plates at {gap.where()} where the ideal "
                              f"observer's {which} is {100 * gap.ceiling:.1f} % [{100 * gap.ceiling_interval[0]:.1f}, "
                              f"{100 * gap.ceiling_interval[1]:.1f}]: a gap of {gap.text()} points: the suite's "
                              "attackers are weak here: privacy is overstated"))
    return flags


def entry_flags(entries: Iterable[Entry], study: Mapping[str, Any] | None) -> list[Flag]:
    """Every flag of every entry (its lens spec decides whether the study's ceiling applies)."""
    return [f for e in entries for f in lens_flags(e.lens, e.profile, e.rows, e.lens_spec, study)]
