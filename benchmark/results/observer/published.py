"""The ideal-observer study (leaderboard/studies/ideal_observer.json) beside the leaderboard and a run.

The study is keyed by lens name and records the lens spec each curve was computed for. A curve
applies to a leaderboard entry or a run's lens only when that spec matches the entry's (`same_lens`:
every number, the mask's Zernike coefficients included, equal to 1e-9 relative; the free-text
description ignored); otherwise the lens was changed (e.g. retrained) since the study and its
ceiling is "not computed". Both specs are compared as today's lens code parses them, so a key
the code has since dropped (`simulation.oversample`) or a default left out does not hide a match.

Consistency. Every reader and chain of an entry is checked against its lens's T = 1 plate ceiling
(`consistency.check_consistency`): the genie's, a proven bound, whose crossing fails the row; a run
also checks its bins against the tighter, marginalised ceiling where the record holds one
(`record["marginal"]`, `marginal_t1_curve`) and reports a crossing of it alone, failing nothing. Entries carry each chain's pooled accuracy over its readable
plates, so the entry check uses one bin from the smallest width they count
(`benchmark.results.ensemble.pooled_min_width`: 32 px for entries scored before plates were scored
from 8 px): a mixture of widths cannot beat the largest ceiling over them. A run checks its own per-plate
records (plates.csv) per width bin (`run_violations`). Beyond the study's widest tabulated width the
curve is compared at its tabulated part (`ceiling_high_in_bin`): a ceiling still rising there could
only raise a false alarm, never hide a violation.
"""

from __future__ import annotations

import dataclasses

import json
import logging
import math
from collections.abc import Mapping, Sequence
from pathlib import Path
from typing import Any

from benchmark.results.entries import LEADERBOARD, Entry
from benchmark.results.observer.ceiling import CeilingCurve
from benchmark.results.observer.consistency import BinAccuracy, Violation, check_consistency
from benchmark.results.ensemble import pooled_min_width
from benchmark.results.plate_scoring import WIDTH_BINS_PX
from benchmark.results.schema import Row, RowError
from benchmark.results.stats import wilson_interval
from lenses import LensSpecError, parse_spec

log = logging.getLogger(__name__)

STUDY = Path("studies") / "ideal_observer.json"
NOT_COMPUTED = "not computed"
_IGNORED_SPEC_KEYS = ("description",)


def load_study(directory: Path = LEADERBOARD) -> dict[str, Any] | None:
    """The study record of `directory` (a leaderboard folder), or None when it has none."""
    path = Path(directory) / STUDY
    return json.loads(path.read_text(encoding="utf-8")) if path.is_file() else None


def _same(a: Any, b: Any) -> bool:
    if isinstance(a, bool) or isinstance(b, bool):
        return a == b
    if isinstance(a, (int, float)) and isinstance(b, (int, float)):
        return math.isclose(a, b, rel_tol=1e-9, abs_tol=1e-12)
    if isinstance(a, dict) and isinstance(b, dict):
        keys = (set(a) | set(b)) - set(_IGNORED_SPEC_KEYS)
        return all(k in a and k in b and _same(a[k], b[k]) for k in keys)
    if isinstance(a, (list, tuple)) and isinstance(b, (list, tuple)):
        return len(a) == len(b) and all(_same(x, y) for x, y in zip(a, b))
    return a == b


def normalized_spec(spec: Mapping[str, Any], where: str = "") -> dict[str, Any] | None:
    """`spec` as the lens code reads it today (`lenses.parse_spec(...).to_dict()`: obsolete keys such as
    `simulation.oversample` dropped, defaults filled in), or None with a warning when it no longer parses."""
    try:  # through JSON: a run's spec dict holds tuples where a stored one holds lists
        return parse_spec(json.loads(json.dumps(dict(spec))), source=where).to_dict()
    except LensSpecError as error:
        log.warning("lens spec of %s does not parse (%s); no ideal-observer ceiling applies to it", where or "?", error)
        return None


def same_lens(study_spec: Mapping[str, Any] | None, spec: Mapping[str, Any] | None) -> bool:
    """True when two lens specs (as stored in entries and the study) describe the same lens: equal after
    both are parsed by today's lens code (`normalized_spec`), so a spec stored with an obsolete key or
    without a default matches; numbers to 1e-9 relative, the description ignored."""
    if study_spec is None or spec is None:
        return False
    a, b = normalized_spec(study_spec, "the ideal-observer study"), normalized_spec(spec, "an entry or run")
    return a is not None and b is not None and _same(a, b)


def spec_differences(study_spec: Mapping[str, Any] | None, spec: Mapping[str, Any] | None, limit: int = 4
                     ) -> list[str]:
    """The dotted keys where two lens specs differ as today's lens code parses them (`same_lens`'s
    comparison), at most `limit` of them; ["spec"] when either is missing or does not parse."""
    a = None if study_spec is None else normalized_spec(study_spec, "the ideal-observer study")
    b = None if spec is None else normalized_spec(spec, "an entry or run")
    if a is None or b is None:
        return ["spec"]
    found: list[str] = []

    def walk(x: Any, y: Any, path: str) -> None:
        if isinstance(x, dict) and isinstance(y, dict):
            for k in sorted((set(x) | set(y)) - set(_IGNORED_SPEC_KEYS)):
                walk(x.get(k), y.get(k), f"{path}.{k}" if path else k)
        elif not _same(x, y):
            found.append(path)
    walk(a, b, "")
    return found[:limit]


def study_record(study: Mapping[str, Any] | None, lens: str, spec: Mapping[str, Any] | None) -> dict | None:
    """The study's record of `lens` (keys t1, t30, ...) when its recorded spec matches `spec`, else None."""
    record = (study or {}).get("lenses", {}).get(lens)
    return record if record is not None and same_lens(record.get("lens_spec"), spec) else None


def t1_curve(record: Mapping[str, Any] | None) -> CeilingCurve | None:
    """The T = 1 genie plate-ceiling curve of a study record (None: no record)."""
    return None if record is None or "t1" not in record else CeilingCurve.from_dict(record["t1"]["curve"])


def marginal_t1_curve(record: Mapping[str, Any] | None) -> CeilingCurve | None:
    """The T = 1 marginalised (tighter) plate-ceiling curve of a study record (`record["marginal"]`, written
    by `python -m benchmark.studies.observer_study --marginal`); None where the study has none (older records)."""
    marginal = None if record is None else record.get("marginal")
    return None if marginal is None or "t1" not in marginal else CeilingCurve.from_dict(marginal["t1"]["curve"])


def entry_accuracies(entry: Entry) -> list[BinAccuracy]:
    """Each reader and chain of `entry` pooled over its seeds: plates read over readable plates, one
    bin [pooled_min_width, inf), with its Wilson 95 % interval. Chains without plates are left out."""
    low = pooled_min_width(entry.rows)
    out = []
    for chain in entry.chains():
        if chain.kind not in ("reader", "chain"):
            continue
        hits = n = 0
        for row in chain.rows:
            acc, count = row.metrics.get("plate_acc"), row.metrics.get("n_plates")
            if acc is None or not count:
                continue
            hits += round(acc * count)
            n += int(count)
        if n:
            out.append(BinAccuracy(chain.attack, entry.lens, low, math.inf, hits / n,
                                   wilson_interval(hits, n), n))
    return out


def entry_violations(entries: Sequence[Entry], study: Mapping[str, Any] | None) -> list[tuple[Entry, Violation]]:
    """Every reader of every entry above its lens's T = 1 ceiling (entries whose lens the study matches)."""
    found = []
    for entry in entries:
        curve = t1_curve(study_record(study, entry.lens, entry.lens_spec))
        if curve is None:
            continue
        found += [(entry, v) for v in check_consistency(entry_accuracies(entry), {entry.lens: curve})]
    for entry, v in found:
        log.error("%s (leaderboard entry %s / %s / %s)", v.message(), entry.lens, entry.profile, entry.scenes)
    return found


def plate_bins(records: Sequence[Mapping[str, Any]], bins_px: Sequence[int] = WIDTH_BINS_PX) -> list[BinAccuracy]:
    """Per (lens, chain, width bin) accuracy of a run's per-plate records (plates.csv: lens, attack,
    width_px, correct), pooled over seeds, with Wilson 95 % intervals; the last bin is open-ended."""
    edges = list(bins_px) + [math.inf]
    counts: dict[tuple[str, str, int], list[int]] = {}
    for r in records:
        width = float(r["width_px"])
        b = next((i for i in range(len(bins_px)) if edges[i] <= width < edges[i + 1]), None)
        if b is None:
            continue
        correct = r["correct"]
        hit = correct.strip().lower() in ("true", "1") if isinstance(correct, str) else bool(correct)
        tally = counts.setdefault((str(r["lens"]), str(r["attack"]), b), [0, 0])
        tally[0] += hit
        tally[1] += 1
    return [BinAccuracy(attack, lens, edges[b], edges[b + 1], hits / n, wilson_interval(hits, n), n)
            for (lens, attack, b), (hits, n) in sorted(counts.items())]


def _crossing(v: Violation) -> dict[str, Any]:
    return {"reader": v.measured.reader, "lens": v.measured.lens, "ceiling": v.ceiling, "low_px": v.measured.low_px,
            "high_px": None if math.isinf(v.measured.high_px) else v.measured.high_px,
            "accuracy": v.measured.accuracy, "interval": list(v.measured.interval),
            "n_plates": v.measured.n_plates, "ceiling_high": v.ceiling_high, "message": v.message()}


def run_violations(records: Sequence[Mapping[str, Any]], lens_info: Mapping[str, Mapping[str, Any]],
                   study: Mapping[str, Any] | None) -> dict[str, Any]:
    """The consistency check of a run (JSON-ready): which lenses were checked against the study, which
    not and why, every violation of the genie's ceiling (`violations`, ceiling "genie": the rows fail)
    and every bin above the tighter ceiling alone (`above_tighter`, ceiling "marginal": reported only),
    each with its message; `tighter_checked`: the lenses whose record holds the tighter ceiling."""
    curves, not_checked = {}, {}
    tighter: dict[str, CeilingCurve] = {}
    for lens, info in lens_info.items():
        record = study_record(study, lens, info.get("spec"))
        if record is None:
            stored = (study or {}).get("lenses", {}).get(lens)
            not_checked[lens] = ("no ideal-observer curve for this lens" if stored is None
                                 else "the study's lens spec differs from this run's in "
                                 + ", ".join(spec_differences(stored.get("lens_spec"), info.get("spec"))))
        else:
            curves[lens] = t1_curve(record)
            marginal = marginal_t1_curve(record)
            if marginal is not None:
                tighter[lens] = marginal
    measured = [m for m in plate_bins(records) if m.lens in curves]
    violations = check_consistency(measured, curves)
    failed = {(v.measured.lens, v.measured.reader, v.measured.low_px) for v in violations}
    above = [v for v in check_consistency([m for m in measured if m.lens in tighter], tighter)
             if (v.measured.lens, v.measured.reader, v.measured.low_px) not in failed]
    return {"summary": _summary_line(sorted(curves), not_checked, len(measured), len(violations), sorted(tighter),
                                     len(above)),
            "study": str(STUDY), "checked": sorted(curves), "tighter_checked": sorted(tighter),
            "not_checked": not_checked, "bins_checked": len(measured),
            "violations": [_crossing(v) for v in violations], "above_tighter": [_crossing(v) for v in above]}


def _summary_line(checked: Sequence[str], not_checked: Mapping[str, str], bins: int, violations: int,
                  tighter: Sequence[str] = (), above_tighter: int = 0) -> str:
    """ceiling_check.json's first line: what was checked, against how many width bins, against which
    ceilings, and why the rest was not (`leaderboard/studies/ideal_observer.json` holds a lens's ceiling
    only for the spec it was computed for: `python -m benchmark.studies.observer_study` recomputes it)."""
    parts = []
    if checked:
        parts.append(f"checked {', '.join(checked)} in {bins} width bin(s): {violations} violation(s)")
        if tighter:
            parts.append(f"{above_tighter} bin(s) above the tighter ceiling alone ({', '.join(tighter)})")
    else:
        parts.append("nothing checked")
    parts += [f"{lens} not checked: {why}" for lens, why in sorted(not_checked.items())]
    return "; ".join(parts)


ABOVE_CEILING = "CEILING VIOLATION"  # how a violation's message starts (``consistency.Violation.message``)


def fail_above_ceiling(rows: Sequence[Row], violations: Sequence[Mapping[str, Any]]) -> list[Row]:
    """`rows` with every row of a chain that reads above its lens's ceiling (``run_violations``) failed:
    no honest attacker can, so the figure is a modelling or scoring error, or a reader that saw the
    answers, and never a result. The failed row keeps its settings and names the violation (stage
    "score"); every seed of the chain fails, since the violation pools them. Only the genie's ceiling
    fails a row (a violation without a "ceiling" key is the genie's); a crossing of the tighter one is
    no proof of an error and is passed over."""
    named = {(v["lens"], v["reader"]): v["message"] for v in violations if v.get("ceiling", "genie") == "genie"}
    out = []
    for row in rows:
        message = named.get((row.lens, row.attack))
        if message is not None and row.ok:
            row = dataclasses.replace(row, status="failed", metrics={}, units=None, notes={},
                                      error=RowError(row.attack, "score", f"{message}; the row is failed"))
        out.append(row)
    return out


def write_run_check(out: Path, records: Sequence[Mapping[str, Any]], lens_info: Mapping[str, Mapping[str, Any]],
                    directory: Path = LEADERBOARD) -> Path:
    """Check a run's plates against the study of `directory`, write ``out/ceiling_check.json`` and
    log every violation as an ERROR (printed by the CLI). Returns the path written."""
    check = run_violations(records, lens_info, load_study(directory))
    for v in check["violations"]:
        log.error("%s", v["message"])
    for v in check["above_tighter"]:
        log.warning("%s", v["message"])
    path = Path(out) / "ceiling_check.json"
    path.write_text(json.dumps(check, indent=1) + "\n", encoding="utf-8")
    return path
