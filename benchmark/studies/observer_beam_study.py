"""The `ideal-observer` reader's search width: how many more plates a wider beam reads, and what it costs.

The reader's beam search (attacks.readers.ideal_observer_reader) keeps a beam of strings per position and
sweeps at most `max_sweeps` times, from each start with each of its beam widths in turn; a wider search finds
a string of higher likelihood where a narrow one stops at a local optimum (under a wide PSF every glyph's
position depends on all the others), yet one wider beam alone takes other paths, not more of them. Each setting
reads the same plates: the quick profile's plate windows of seed 0 (`benchmark.runner.tasks.plate_set`, the
run's noise) whose widest scored plate lies in the width range asked, through the lens built from its quick
leaderboard entry. Per lens and range: plates read by each setting, the paired difference (McNemar's exact
test, Newcombe's interval), seconds per plate and the machine load.

Writes leaderboard/studies/ideal_observer_beam.json.
`python -m benchmark.studies.observer_beam_study [--case LENS LOW HIGH ...] [--plates N]`.
"""

from __future__ import annotations

import json
import logging
import os
import time
from pathlib import Path

from attacks.readers.ideal_observer_reader import IdealObserverReader
from benchmark.results.stats import paired_accuracy_difference, paired_table
from benchmark.runner.evaluation import read_plates
from benchmark.runner.tasks import fit_context, plate_set
from benchmark.studies.observer_study import REPO, quick_lenses
from benchmark.studies.reader_study import quota_config

OUT_JSON = REPO / "leaderboard" / "studies" / "ideal_observer_beam.json"
SETTINGS = {"beam 3, 4 sweeps": ((3,), 4), "beam 6, 6 sweeps": ((6,), 6), "beams 3 then 6, 6 sweeps": ((3, 6), 6)}
# The width ranges where the cascade reads on the blurring lenses (the bins the other chains leave open).
CASES = (("os-d-1000", 48, 64), ("os-d-1000", 64, 96), ("gp", 32, 48), ("defocus", 48, 64))

log = logging.getLogger(__name__)


def read_case(lens_name: str, low: float, high: float, n_plates: int,
              settings: dict[str, tuple[tuple[int, ...], int]]) -> dict:
    """Every setting's per-plate outcomes on the plate windows of `lens_name` in [low, high) px (module docstring)."""
    cfg = quota_config((lens_name,), ("ideal-observer",), n_plates, 0)
    lens = quick_lenses()[lens_name]
    plates = plate_set(cfg, 0, lens)
    if plates is None:
        raise RuntimeError(f"the quick profile reads no plate windows for lens {lens_name!r}")
    keep = [i for i, s in enumerate(plates.scenes)
            if low <= max(p.box_xyxy[2] - p.box_xyxy[0] for p in s.plates) < high]
    out: dict = {"lens": lens_name, "low_px": low, "high_px": high, "settings": {}}
    for label, (beams, sweeps) in settings.items():
        reader = IdealObserverReader(beams=beams, max_sweeps=sweeps)
        reader.fit(fit_context(lens, cfg, 0, None))
        t0 = time.perf_counter()
        outcomes, _, _ = read_plates(reader, [plates.sensor[i] for i in keep], [plates.scenes[i] for i in keep],
                                     cfg.profile.batch_size, cfg.device)
        seconds = time.perf_counter() - t0
        chosen = [o for o in outcomes if low <= o.width_px < high]
        out["settings"][label] = {"beams": list(beams), "max_sweeps": sweeps, "read": sum(o.correct for o in chosen),
                                  "plates": len(chosen), "s_per_plate": round(seconds / max(len(outcomes), 1), 2),
                                  "load_average": round(os.getloadavg()[0], 2),
                                  "correct": [bool(o.correct) for o in chosen], "truth": [o.truth for o in chosen]}
        log.info("%s %g-%g px, %s: %d of %d read, %.0f s", lens_name, low, high, label,
                 out["settings"][label]["read"], len(chosen), seconds)
    return out


def paired(case: dict, a: str, b: str) -> dict:
    """Setting `a` against `b` on the same plates: the difference of plates read, its interval and p."""
    table = paired_table(case["settings"][a]["correct"], case["settings"][b]["correct"])
    comparison = paired_accuracy_difference(*(int(c) for c in table))
    return {"a": a, "b": b, "gained": int(table[1]), "lost": int(table[2]), "difference": round(comparison.difference, 4),
            "interval": [round(comparison.low, 4), round(comparison.high, 4)], "p_value": comparison.p_value}


def run_study(cases=CASES, n_plates: int = 25, settings=SETTINGS, out_json: Path | None = OUT_JSON) -> dict:
    """Read every case with every setting; per case and pooled, the paired comparison of the last setting (the
    reader's default) against the first and against each other one (`paired_with`)."""
    labels = list(settings)
    record: dict = {"profile": "quick", "seed": 0, "n_plates_target": n_plates, "cases": []}
    for lens_name, low, high in cases:  # written after each case: an interrupted study keeps what it read
        case = read_case(lens_name, low, high, n_plates, settings)
        case["paired"] = paired(case, labels[-1], labels[0])
        case["paired_with"] = {b: paired(case, labels[-1], b) for b in labels[1:-1]}
        record["cases"].append(case)
        pooled = {"lens": "all", "low_px": None, "high_px": None, "settings": {
            label: {"correct": [c for k in record["cases"] for c in k["settings"][label]["correct"]]}
            for label in labels}}
        record["pooled"] = paired(pooled, labels[-1], labels[0])
        record["pooled_with"] = {b: paired(pooled, labels[-1], b) for b in labels[1:-1]}
        if out_json is not None:
            out_json.parent.mkdir(parents=True, exist_ok=True)
            out_json.write_text(json.dumps(record, indent=1) + "\n", encoding="utf-8")
    return record


def main(argv: list[str] | None = None) -> dict:
    import argparse
    parser = argparse.ArgumentParser(prog="python -m benchmark.studies.observer_beam_study", description=__doc__)
    parser.add_argument("--case", nargs=3, action="append", metavar=("LENS", "LOW", "HIGH"),
                        help="a lens and a width range in px (repeat; default: " + ", ".join(
                            f"{n} {lo}-{hi}" for n, lo, hi in CASES) + ")")
    parser.add_argument("--plates", type=int, default=25, help="plates per width bin (the plate set's quota)")
    parser.add_argument("--out", type=Path, default=OUT_JSON)
    args = parser.parse_args(argv)
    logging.basicConfig(level=logging.INFO, format="%(asctime)s %(message)s")
    cases = [(n, float(lo), float(hi)) for n, lo, hi in args.case] if args.case else CASES
    unknown = sorted({n for n, _, _ in cases} - set(quick_lenses()))
    if unknown:
        parser.error(f"--case: unknown lens {unknown}; valid: {sorted(quick_lenses())}")
    record = run_study(cases, args.plates, out_json=args.out)
    for p in (record["pooled"], *record["pooled_with"].values()):
        print(f"{p['a']} against {p['b']}: +{p['gained']} / -{p['lost']} plates, {100 * p['difference']:+.1f} pt "
              f"[{100 * p['interval'][0]:+.1f}, {100 * p['interval'][1]:+.1f}], p = {p['p_value']:.3g}")
    return record


if __name__ == "__main__":
    main()
