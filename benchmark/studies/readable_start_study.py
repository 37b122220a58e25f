"""Measure where readable plates start (benchmark.results.readable_start) and ship the measurement.

    python -m benchmark.studies.readable_start_study [--readers learned-reader lpdr-oracle] [--seed 0]

Reads the sharp plate windows of the quick profile (``benchmark.runner.tasks.plate_set`` with no
lens: every scored plate from 8 px, 50 per width bin) with each reader, fitted as a run fits it for
the sharp scene (``learned-reader``: its shipped sharp start, no fine-tune), and writes per reader
and width bin the plates read, then the start: the lower edge of the smallest bin where the best
reader reads at least half of the plates. The record (with date, commit, machine, torch, seconds and
load average) goes to ``benchmark/results/readable_start.json``; the scoring reads it at import.
"""

from __future__ import annotations

import argparse
import json
import logging
import os
import platform
import time
from collections.abc import Sequence
from pathlib import Path

import numpy as np
import torch

import attacks
from benchmark.results.plate_scoring import WIDTH_BINS_PX
from benchmark.results.readable_start import MEASUREMENT, READ_SHARE, start_from
from benchmark.runner.config import RunConfig
from benchmark.runner.evaluation import read_plates
from benchmark.runner.tasks import fit_context, plate_set
from benchmark.store.cache import atomic_write_text, cache_root
from benchmark.store.profiles import get_profile
from benchmark.store.provenance import git_commit

READERS = ("learned-reader", "lpdr-oracle")
PROFILE = "quick"

log = logging.getLogger(__name__)


def bin_counts(widths: np.ndarray, correct: np.ndarray, bins_px: Sequence[int] = WIDTH_BINS_PX) -> list[dict]:
    """Per width bin (lower edges `bins_px`, the last open above): plates and plates read."""
    edges = [*bins_px, float("inf")]
    out = []
    for low, high in zip(edges[:-1], edges[1:]):
        inside = (widths >= low) & (widths < high)
        out.append({"low_px": int(low), "high_px": None if high == float("inf") else int(high),
                    "hits": int(correct[inside].sum()), "n": int(inside.sum())})
    return out


def best_bins(per_reader: dict[str, list[dict]]) -> list[dict]:
    """Per bin, the counts of the reader that read the most plates there (named in ``reader``)."""
    names = list(per_reader)
    out = []
    for i, first in enumerate(per_reader[names[0]]):
        best = max(names, key=lambda n: per_reader[n][i]["hits"])
        out.append({**per_reader[best][i], "reader": best})
    return out


def measure(readers: Sequence[str] = READERS, seed: int = 0, cache_dir: Path | None = None) -> dict:
    """The record (module docstring), not written."""
    cfg = RunConfig(lenses=[], attacks=list(readers), scenes="synthetic", seeds=[seed], profile=get_profile(PROFILE),
                    cache_dir=cache_dir or cache_root())
    plates = plate_set(cfg, seed, None)
    if plates is None or not plates.scenes:
        raise RuntimeError(f"the {PROFILE} profile gives no plate windows to measure on")
    per_reader, seconds = {}, {}
    load_before = os.getloadavg()[0]
    for name in readers:
        reader = attacks.load(name)
        t0 = time.perf_counter()
        reader.fit(fit_context(None, cfg, seed, None))
        outcomes, _, _ = read_plates(reader, plates.sensor, plates.scenes, cfg.profile.batch_size, cfg.device)
        seconds[name] = round(time.perf_counter() - t0, 1)
        widths = np.array([o.width_px for o in outcomes], dtype=float)
        per_reader[name] = bin_counts(widths, np.array([o.correct for o in outcomes], dtype=bool))
        log.info("%s: %s", name, ", ".join(f"{b['low_px']} px {b['hits']}/{b['n']}" for b in per_reader[name]))
    bins = best_bins(per_reader)
    start = start_from(bins)
    if start is None:
        raise RuntimeError(f"no reader of {list(readers)} reads {READ_SHARE:.0%} of the sharp plates in any width bin")
    return {"start_px": start, "read_share": READ_SHARE, "bins": bins, "per_reader": per_reader,
            "plates": len(plates.scenes), "frames": plates.n_frames, "profile": PROFILE, "seed": seed,
            "scenes": "synthetic", "readers": list(readers), "seconds": seconds,
            "provenance": {"date": time.strftime("%Y-%m-%d", time.gmtime()), "git_commit": git_commit(),
                           "torch": torch.__version__, "machine": f"{platform.machine()}, {os.cpu_count()} cores",
                           "load_average": [load_before, os.getloadavg()[0]]}}


def main(argv: list[str] | None = None) -> dict:
    parser = argparse.ArgumentParser(prog="python -m benchmark.studies.readable_start_study",
                                     description=__doc__.split("\n")[0])
    parser.add_argument("--readers", nargs="+", default=list(READERS), help=f"readers to measure (default {READERS})")
    parser.add_argument("--seed", type=int, default=0)
    parser.add_argument("--out", type=Path, default=MEASUREMENT, help=f"record to write (default {MEASUREMENT})")
    args = parser.parse_args(argv)
    logging.basicConfig(level=logging.INFO, format="%(asctime)s %(name)s %(message)s")
    record = measure(args.readers, args.seed)
    atomic_write_text(args.out, json.dumps(record, indent=1) + "\n")
    print(f"plates are readable from {record['start_px']} px; wrote {args.out}")
    return record


if __name__ == "__main__":
    main()
