"""``learned-reader-psf`` against the published readers on the entries' own plates: ``python -m benchmark.studies.psf_reader_study``.

For each lens (default: ideal, defocus, gp, os, os-d-1000) it rebuilds the lens of the published quick
entry at seed 0 (its ``lens_spec``), makes the run's plate set exactly as the run did
(``benchmark.runner.tasks.plate_set``: the same val frames, windows and sensor noise), and reads it with
``learned-reader-psf`` (its shipped family network, zero-shot as the standard ensemble reads; that network
fine-tuned on the lens, ``learned-reader-psf-tuned``; and the sharp-plate start it was pre-trained from; with
``--family-weights FILE`` also with the learned reader's network holding those weights on the sensor image:
an unshipped lens-family pre-training). Its per-plate outcomes are
paired by plate id with the entry's seed-0 rows: the per-lens fine-tuned ``learned-reader``, the
strongest single reader chain of the entry, and the entry's ensemble (a plate read by any of its reader
chains). The plate ids must agree (that proves the pairing; a mismatch is reported, not paired).
Per width bin: accuracies with Wilson intervals; pooled over the plates of 32 px and wider: paired
bootstrap differences (``benchmark.results.stats``) and what the ensemble would read with the reader
added. Writes ``leaderboard/studies/psf_reader.json``.
"""

from __future__ import annotations

import argparse
import json
import os
import time
from pathlib import Path
from typing import Any

import numpy as np
import torch

from attacks.base import AttackBudget, FitContext, Reader
from attacks.readers.learned_reader import LearnedReader, unpack_weights
from attacks.readers.learned_reader_psf import LearnedReaderPSF, LearnedReaderPSFTuned
from attacks.readers.plates.plate_sim import psf_radius_px
from attacks.training.shipped_weights import read_checked
from benchmark.results import stats
from benchmark.results.plate_scoring import WIDTH_BINS_PX
from benchmark.runner.config import RunConfig
from benchmark.runner.evaluation import PlateSet, read_plates
from benchmark.runner.rows import plate_units
from benchmark.runner.tasks import plate_set
from benchmark.store.profiles import Profile, get_profile
from benchmark.store.provenance import git_commit, package_versions
from lenses.lens import Lens
from lenses.spec import parse_spec

__all__ = ["lens_plates", "main", "measure_lens", "plate_outcomes"]

ROOT = Path(__file__).resolve().parents[2]
ENTRIES = ROOT / "leaderboard" / "entries"
OUT = ROOT / "leaderboard" / "studies" / "psf_reader.json"
LENSES = ("ideal", "defocus", "gp", "os", "os-d-1000")
FROM_PX = 32  # the pooled comparisons take every plate at least this wide (the table's "readable" plates)


def _entry_outcomes(entry: dict[str, Any], seed: int) -> dict[str, dict[str, tuple[int, int]]]:
    """Per reader chain of the entry at `seed`: plate id -> (correct, width px)."""
    out = {}
    for row in entry["rows"]:
        units = row.get("units")
        if row["kind"] != "reader" or row["seed"] != seed or row["status"] != "ok" or not units:
            continue
        ids = [units["prefix"] + i for i in entry["unit_ids"][units["ids"]]]
        values = units["values"]
        out[row["attack"]] = dict(zip(ids, zip(values["correct"], values["width_px"])))
    return out


def _bins(hits: list[int], widths: list[int]) -> dict[str, Any]:
    out = {}
    for low, high in zip(WIDTH_BINS_PX, [*WIDTH_BINS_PX[1:], None]):
        chosen = [h for h, w in zip(hits, widths) if w >= low and (high is None or w < high)]
        if chosen:
            lo, hi = stats.wilson_interval(sum(chosen), len(chosen))
            out[f"{low}-{high or 'inf'}"] = {"accuracy": round(float(np.mean(chosen)), 4), "low": round(lo, 4),
                                              "high": round(hi, 4), "n": len(chosen)}
    return out


def _compare(a: list[int], b: list[int]) -> dict[str, Any]:
    c = stats.paired_bootstrap(a, b)
    return {"difference_pt": round(100 * c.difference, 2), "low_pt": round(100 * c.low, 2),
            "high_pt": round(100 * c.high, 2), "p_value": c.p_value, "verdict": stats.verdict(c, "greater").label,
            "n": c.n}


def lens_plates(name: str, seed: int = 0) -> tuple[dict[str, Any], Profile, Lens, PlateSet]:
    """The published quick entry of lens ``name`` (its JSON), the quick profile, the entry's lens and the
    plate set a run of ``seed`` reads (rebuilt: the same plate ids as the entry's rows)."""
    entry = json.loads((ENTRIES / f"{name}__quick__synthetic.json").read_text())
    profile = get_profile("quick")
    lens = Lens(parse_spec(entry["lens_spec"], f"{name} entry"))
    cfg = RunConfig(lenses=[name], attacks=[], scenes="synthetic", profile=profile, seeds=[seed])
    with torch.no_grad():
        plates = plate_set(cfg, seed, lens)
    assert plates is not None, "the quick profile reads plate windows"
    return entry, profile, lens, plates


def plate_outcomes(reader: Reader, plates: PlateSet, profile: Profile) -> dict[str, tuple[int, int]]:
    """Per plate id of ``plates``: (read exactly by the fitted ``reader``, width px), as a run scores it."""
    outcomes, _, _ = read_plates(reader, plates.sensor, plates.scenes, profile.batch_size, "cpu")
    units = plate_units(outcomes)
    return dict(zip((units.prefix + i for i in units.ids), zip(units.values["correct"], units.values["width_px"])))


def measure_lens(name: str, family_weights: Path | None = None, seed: int = 0) -> dict[str, Any]:
    """The study's record for one lens (module docs)."""
    t0 = time.perf_counter()
    entry, profile, lens, plates = lens_plates(name, seed)
    seconds = {"plate_set": round(time.perf_counter() - t0, 1)}
    readers: dict[str, LearnedReader] = {"learned-reader-psf": LearnedReaderPSF(),
                                         "learned-reader-psf-tuned": LearnedReaderPSFTuned(),
                                         "learned-reader-psf (sharp start)": LearnedReaderPSF(family=False)}
    if family_weights is not None:
        family = LearnedReader(use_shipped_fit=False)
        family.fit(FitContext(budget=AttackBudget(profile="quick")))  # the sharp start, no lens: then swap in
        provenance = json.loads(family_weights.with_suffix(".json").read_text())
        assert family.net is not None
        unpack_weights(family.net, read_checked(family_weights, provenance["size"], provenance["sha256"],
                                                "the family pre-training"))
        family.spread_px = psf_radius_px(lens.psf().detach())  # its crops as its training cut them for this lens
        readers["family-start"] = family
    ours: dict[str, dict[str, tuple[int, int]]] = {}
    fits: dict[str, Any] = {}
    for label, reader in readers.items():
        t0 = time.perf_counter()
        if isinstance(reader, LearnedReaderPSF):
            reader.fit(FitContext(lens=lens, budget=AttackBudget(profile="quick")))
            if reader.curve is not None:
                fits[label] = {"fit_s": round(time.perf_counter() - t0, 1), "steps": reader.curve.steps,
                               "held_out": [round(a, 4) for a in reader.curve.accuracy],
                               "kept_step": reader.curve.best_step, "stopped": reader.curve.stopped}
        ours[label] = plate_outcomes(reader, plates, profile)
        seconds[label] = round(time.perf_counter() - t0, 1)
    published = _entry_outcomes(entry, seed)
    ids = sorted(ours["learned-reader-psf"])
    if set(ids) != set(published["learned-reader"]):
        return {"lens_spec": entry["lens_spec"], "seconds": seconds, "paired": False,
                "mismatch": {"ours": len(ids), "published": len(published["learned-reader"]),
                             "common": len(set(ids) & set(published["learned-reader"]))}}
    readable = [i for i in ids if ours["learned-reader-psf"][i][1] >= FROM_PX]
    widths = [ours["learned-reader-psf"][i][1] for i in ids]

    def hits(table: dict[str, tuple[int, int]], chosen: list[str]) -> list[int]:
        return [int(table[i][0]) for i in chosen]

    def union(added: dict[str, tuple[int, int]] | None = None, left_out: str | None = None) -> dict[str, tuple[int, int]]:
        """Per plate: read by any published chain but ``left_out``, or by ``added``; with its width."""
        return {i: (int(bool(added and added[i][0])
                        or any(p[i][0] for a, p in published.items() if a != left_out and i in p)),
                    ours["learned-reader-psf"][i][1]) for i in ids}

    ensemble = union()
    with_psf = union(ours["learned-reader-psf"])
    # The same without the per-lens fine-tuned learned-reader: what it still adds once learned-reader-psf is in.
    without_tuned = union(ours["learned-reader-psf"], left_out="learned-reader")
    tuned = ours["learned-reader-psf-tuned"]
    # The ensemble with the per-lens fine-tuned reader in place of the zero-shot one, with and without learned-reader.
    with_tuned = union(tuned)
    tuned_without = union(tuned, left_out="learned-reader")
    best = max((a for a in published if a != "learned-reader"), key=lambda a: sum(hits(published[a], readable)))
    table = {**ours, "learned-reader": published["learned-reader"],
             f"best published chain ({best})": published[best], "published ensemble": ensemble,
             "published ensemble + learned-reader-psf": with_psf,
             "published ensemble + learned-reader-psf - learned-reader": without_tuned,
             "published ensemble + learned-reader-psf-tuned": with_tuned,
             "published ensemble + learned-reader-psf-tuned - learned-reader": tuned_without}
    record: dict[str, Any] = {
        "lens_spec": entry["lens_spec"], "seconds": seconds, "fits": fits, "paired": True, "n_plates": len(ids),
        "n_from_32px": len(readable),
        "readers": {label: {"bins": _bins(hits(t, ids), widths),
                            f"from_{FROM_PX}px": round(float(np.mean(hits(t, readable))), 4)} for label, t in table.items()},
        "paired_from_32px": {
            "learned-reader-psf - learned-reader": _compare(hits(ours["learned-reader-psf"], readable),
                                                            hits(published["learned-reader"], readable)),
            "learned-reader-psf - best published chain": _compare(hits(ours["learned-reader-psf"], readable),
                                                                  hits(published[best], readable)),
            "ensemble with it - published ensemble": _compare(hits(with_psf, readable), hits(ensemble, readable)),
            "ensemble with it - the same without learned-reader": _compare(hits(with_psf, readable),
                                                                         hits(without_tuned, readable)),
            "learned-reader-psf-tuned - learned-reader-psf": _compare(hits(tuned, readable),
                                                                      hits(ours["learned-reader-psf"], readable)),
            "ensemble with it tuned - ensemble with it": _compare(hits(with_tuned, readable), hits(with_psf, readable)),
            "ensemble with it tuned - the same without learned-reader": _compare(hits(with_tuned, readable),
                                                                               hits(tuned_without, readable)),
            "learned-reader-psf - its sharp start": _compare(hits(ours["learned-reader-psf"], readable),
                                                             hits(ours["learned-reader-psf (sharp start)"], readable)),
            **({"family-start - learned-reader": _compare(hits(ours["family-start"], readable),
                                                          hits(published["learned-reader"], readable))}
               if "family-start" in ours else {})},
    }
    return record


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--lens", action="append", default=None, help="lens (repeatable; default: %s)" % ", ".join(LENSES))
    parser.add_argument("--family-weights", type=Path, default=None,
                        help="a learned-reader weights file (with its .json) to read the sensor image with too")
    parser.add_argument("--out", type=Path, default=OUT)
    args = parser.parse_args(argv)
    study: dict[str, Any] = json.loads(args.out.read_text()) if args.out.exists() else {}
    study.update({"commit": git_commit(), "packages": package_versions(), "threads": torch.get_num_threads(),
                  "load_average": [round(x, 2) for x in os.getloadavg()], "seed": 0, "pooled_from_px": FROM_PX})
    study.setdefault("lenses", {})
    for name in args.lens or list(LENSES):
        t0 = time.perf_counter()
        record = measure_lens(name, args.family_weights)
        record["seconds"]["total"] = round(time.perf_counter() - t0, 1)
        study["lenses"][name] = record
        if record["paired"]:
            line = ", ".join(f"{r} {100 * v[f'from_{FROM_PX}px']:.1f} %" for r, v in record["readers"].items())
            print(f"{name}: plates from {FROM_PX} px read ({record['n_from_32px']}): {line}")
        else:
            print(f"{name}: plate ids do not match the entry's ({record['mismatch']}); not paired")
        args.out.write_text(json.dumps(study, indent=1) + "\n")
    print(f"wrote {args.out}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
