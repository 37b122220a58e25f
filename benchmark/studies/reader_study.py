"""The `ideal-observer` reader beside EasyOCR (`lpdr-oracle`): exact-plate accuracy per plate width.

Both readers read the same plates: the plate windows of the quick profile's synthetic validation
frames (`benchmark.runner.tasks.plate_set`: scored plates from 8 px wide, a quota per width bin, with
their vehicle and context), seen through each lens as the run sees them (`benchmark.runner.sensing.sense_windows`, the
run's noise), each lens built from its quick leaderboard entry's spec (co-designed coefficients
included, never retrained). Both are given ground truth where the run gives it (`lpdr-oracle` the
vehicle boxes, `ideal-observer` the plate boxes). Accuracy is pooled per width bin of
`benchmark.results.plate_scoring.WIDTH_BINS_PX` with its Wilson 95 % interval and the number of plates,
and every bin is checked against the lens's T = 1 ceiling (`benchmark.results.observer.published`), the
violations logged as errors and kept in the record.

Writes leaderboard/studies/ideal_observer_readers.json; the ceiling chart draws it
(benchmark.results.charts.ideal_observer_chart). Cost: the ideal observer's beam search takes seconds per plate,
so the sample is a few plates per width bin and lens (`n_plates`), stated in the record.
"""

from __future__ import annotations

import dataclasses
import json
import logging
import math
import os
import time
from pathlib import Path

import attacks
from benchmark.runner.evaluation import read_plates
from benchmark.results.observer.published import load_study, plate_bins, run_violations
from benchmark.studies.observer_study import REPO, quick_lens_specs, quick_lenses
from benchmark.store.profiles import get_profile
from benchmark.store.cache import cache_root
from benchmark.runner.config import RunConfig
from benchmark.runner.tasks import fit_context, plate_set

READERS = ("ideal-observer", "lpdr-oracle")
LENSES = ("ideal", "defocus", "os-d-1000")
OUT_JSON = REPO / "leaderboard" / "studies" / "ideal_observer_readers.json"

log = logging.getLogger(__name__)


def read_lens(name: str, cfg: RunConfig, readers: tuple[str, ...], seed: int) -> tuple[list[dict], dict]:
    """Per-plate records (lens, attack, width_px, correct, truth, read) of every reader on the plate
    windows of lens `name`, and per reader its seconds and plates."""
    lens = quick_lenses()[name]
    plates = plate_set(cfg, seed, lens)
    if plates is None or not plates.scenes:
        raise RuntimeError(f"no readable plate windows for lens {name!r} (profile {cfg.profile.name})")
    records, timing = [], {}
    for reader_name in readers:
        reader = attacks.load(reader_name)
        reader.fit(fit_context(lens, cfg, seed, None))
        t0 = time.perf_counter()
        outcomes, _, _ = read_plates(reader, plates.sensor, plates.scenes, cfg.profile.batch_size, cfg.device)
        seconds = time.perf_counter() - t0
        timing[reader_name] = {"seconds": seconds, "n_plates": len(outcomes),
                               "s_per_plate": seconds / max(len(outcomes), 1), "load_average": os.getloadavg()[0]}
        records += [{"lens": name, "attack": reader_name, "width_px": o.width_px, "correct": o.correct,
                     "truth": o.truth, "read": o.read} for o in outcomes]
        log.info("%s / %s: %d of %d plates read exactly, %.0f s", name, reader_name,
                 sum(o.correct for o in outcomes), len(outcomes), seconds)
    return records, timing


def summarise(records: list[dict], lens_specs: dict[str, dict], study: dict | None) -> dict:
    """Per lens and reader the accuracy per width bin (Wilson 95 %) and overall, and the consistency
    check of every bin against the study's ceilings (`run_violations`)."""
    out: dict = {}
    for m in plate_bins(records):
        bins = out.setdefault(m.lens, {}).setdefault(m.reader, {"bins": []})["bins"]
        bins.append({"low_px": m.low_px, "high_px": None if math.isinf(m.high_px) else m.high_px,
                     "accuracy": m.accuracy, "interval": list(m.interval), "n_plates": m.n_plates})
    check = run_violations(records, {lens: {"spec": spec} for lens, spec in lens_specs.items()}, study)
    for v in check["violations"]:
        log.error("%s", v["message"])
    return {"lenses": out, "consistency": check}


def quota_config(names: tuple[str, ...], readers: tuple[str, ...], n_plates: int, seed: int,
                 cache_dir: Path | None = None) -> RunConfig:
    """The quick profile's run configuration with a quota of `n_plates` plate windows per width bin."""
    profile = dataclasses.replace(get_profile("quick"), plates_per_width_bin=n_plates, plates_per_wide_bin=n_plates)
    return RunConfig(lenses=list(names), attacks=list(readers), scenes="synthetic", profile=profile, seeds=[seed],
                     cache_dir=cache_dir or cache_root())


def run_reader_study(names: tuple[str, ...] = LENSES, readers: tuple[str, ...] = READERS, n_plates: int = 4,
                     seed: int = 0, out_json: Path | None = OUT_JSON, cache_dir: Path | None = None) -> dict:
    """Read `n_plates` plates per width bin and lens (the run's plate set with that quota) with each
    reader; write and return the record (module docstring)."""
    cfg = quota_config(names, readers, n_plates, seed, cache_dir)
    specs = quick_lens_specs()
    unknown = [n for n in names if n not in specs]
    if unknown:
        raise ValueError(f"lenses {unknown} are not on the quick leaderboard; valid: {sorted(specs)}")
    records: list[dict] = []
    timing: dict = {}
    record: dict = {}
    for name in names:  # the record is written after each lens: an interrupted study keeps what it read
        lens_records, timing[name] = read_lens(name, cfg, readers, seed)
        records += lens_records
        done = {n: specs[n] for n in timing}
        record = {"profile": "quick", "scenes": "synthetic", "seed": seed, "n_plates_target": n_plates,
                  "readers": list(readers), "lens_specs": done, "timing": timing,
                  **summarise(records, done, load_study(REPO / "leaderboard")), "plates": records}
        if out_json is not None:
            out_json.parent.mkdir(parents=True, exist_ok=True)
            out_json.write_text(json.dumps(record, indent=1) + "\n", encoding="utf-8")
    return record


def combine(parts: list[Path], out_json: Path | None = OUT_JSON) -> dict:
    """One record from reader studies run apart (e.g. one lens per process): their plates and timings
    together, summarised and checked again against the study as it stands now; written to `out_json`.
    A lens read again in a later part replaces that lens's plates, spec and timing from earlier parts
    (re-reading a lens whose spec changed never doubles its plates)."""
    records: list[dict] = []
    timing: dict = {}
    specs: dict = {}
    first = None
    for path in parts:
        part = json.loads(Path(path).read_text(encoding="utf-8"))
        first = first or part
        if any(part[k] != first[k] for k in ("profile", "scenes", "seed", "n_plates_target", "readers")):
            raise ValueError(f"{path} was read with other settings than {parts[0]}; they cannot be combined")
        again = set(part["lens_specs"])
        records = [r for r in records if r["lens"] not in again] + part["plates"]
        timing = {k: v for k, v in timing.items() if k not in again} | part["timing"]
        specs.update(part["lens_specs"])
    if first is None:
        raise ValueError("combine needs at least one reader-study file")
    record = {**{k: first[k] for k in ("profile", "scenes", "seed", "n_plates_target", "readers")},
              "lens_specs": specs, "timing": timing,
              **summarise(records, specs, load_study(REPO / "leaderboard")), "plates": records}
    if out_json is not None:
        out_json.write_text(json.dumps(record, indent=1) + "\n", encoding="utf-8")
    return record


def main(argv: list[str] | None = None) -> dict:
    """`python -m benchmark.studies.reader_study [--lens NAME ...] [--plates N] [--seed S]`."""
    import argparse
    parser = argparse.ArgumentParser(prog="python -m benchmark.studies.reader_study",
                                     description=__doc__.split("\n")[0])
    parser.add_argument("--lens", action="append", help=f"quick-leaderboard lens (repeat; default {LENSES})")
    parser.add_argument("--plates", type=int, default=4, help="plates per width bin and lens (at most)")
    parser.add_argument("--seed", type=int, default=0)
    parser.add_argument("--out", type=Path, default=OUT_JSON, help=f"record to write (default {OUT_JSON})")
    parser.add_argument("--combine", type=Path, nargs="+", help="only combine these records into --out")
    args = parser.parse_args(argv)
    logging.basicConfig(level=logging.INFO, format="%(asctime)s %(name)s %(message)s")
    if args.combine:
        return combine(args.combine, args.out)
    return run_reader_study(tuple(args.lens) if args.lens else LENSES, n_plates=args.plates, seed=args.seed,
                            out_json=args.out)


if __name__ == "__main__":
    main()
