"""``learned-reader``'s per-lens fine-tune on a shorter schedule, against the published fit, per plate:
``python -m benchmark.studies.reader_schedule_study [--lens L ...] [--steps N]``.

The published quick fits run a cosine schedule over 2,400 steps and never stop before step 1,200
(``BUDGETS["quick"]``): 260-310 s a lens on 2 cores, most of a lens's per-lens fit time. A one-cycle
schedule anneals to zero at its own end, so a shorter cycle may reach the same reader in a fraction of
the steps. Per lens (the published quick entry's lens, seed 0), this study fits the reader from the same
sharp start on a candidate budget (``candidate``: the quick budget with ``max_steps`` = ``--steps`` and
``lr`` = ``--lr``, every evaluation run, no early stop) and reads the entry's own plates with it (the run's plate set rebuilt;
ids checked), then pairs per plate, from 32 px (paired bootstrap, 95 %):

- the candidate against the published ``learned-reader`` row (the long fit);
- the ensemble a run now has on those plates (the published chains, ``learned-reader-psf`` zero-shot)
  with the candidate in place of the long fit, against the same with the long fit.

Writes ``leaderboard/studies/reader_schedule.json`` (merged per lens and candidate): the candidate budget, each fit's
held-out curve and seconds, per-bin accuracies and the paired differences, load average, commit.
"""

from __future__ import annotations

import argparse
import dataclasses
import json
import os
import sys
import time
from pathlib import Path
from typing import Any

import numpy as np
import torch

from attacks.base import AttackBudget, FitContext
from attacks.readers.learned_reader import BUDGETS, LearnedReader
from attacks.readers.learned_reader_psf import LearnedReaderPSF
from attacks.training.plate_reader_training import ReaderBudget
from benchmark.store.provenance import git_commit, package_versions
from benchmark.studies.psf_reader_study import (
    FROM_PX, LENSES, _bins, _compare, _entry_outcomes, lens_plates, plate_outcomes)

__all__ = ["candidate", "label", "main", "measure_lens", "published_fit"]

ROOT = Path(__file__).resolve().parents[2]
OUT = ROOT / "leaderboard" / "studies" / "reader_schedule.json"


def candidate(steps: int, lr: float) -> ReaderBudget:
    """The quick fine-tune on a ``steps``-step schedule peaking at ``lr``, evaluated every sixth of it, run
    to its end."""
    every = max(1, steps // 6)
    return dataclasses.replace(BUDGETS["quick"], max_steps=steps, lr=lr, eval_every=every, min_steps=steps)


def label(budget: ReaderBudget) -> str:
    """The key a candidate's records are kept under."""
    return f"{budget.max_steps} steps, lr {budget.lr:g}"


class _Scheduled(LearnedReader):
    """``learned-reader`` with the candidate's fine-tune budget (and no shipped or cached fit)."""

    def __init__(self, budget: ReaderBudget) -> None:
        super().__init__(use_shipped_fit=False)
        self._budget = budget

    def fine_tune_budget(self, profile: str) -> ReaderBudget:
        return self._budget


def published_fit(entry: dict[str, Any], seed: int = 0) -> dict[str, Any]:
    """How the entry's ``learned-reader`` fit of ``seed`` ended (its row's notes) and when it was run."""
    row = next(r for r in entry["rows"] if r["attack"] == "learned-reader" and r["seed"] == seed)
    return {**{k: v for k, v in row["notes"].items() if k.startswith("fit_")}, "date": row["provenance"].get("date")}


def measure_lens(name: str, budget: ReaderBudget, seed: int = 0) -> dict[str, Any]:
    """The study's record for one lens (module docs)."""
    entry, profile, lens, plates = lens_plates(name, seed)
    ours: dict[str, dict[str, tuple[int, int]]] = {}
    record: dict[str, Any] = {"lens_spec": entry["lens_spec"], "published_fit": published_fit(entry, seed)}
    for label, reader in (("candidate", _Scheduled(budget)), ("learned-reader-psf", LearnedReaderPSF())):
        t0 = time.perf_counter()
        reader.fit(FitContext(lens=lens, budget=AttackBudget(profile="quick")))
        fit_s = time.perf_counter() - t0
        if label == "candidate" and reader.curve is not None:
            record["fit"] = {"fit_s": round(fit_s, 1), "steps": reader.curve.steps,
                             "held_out": [round(a, 4) for a in reader.curve.accuracy],
                             "kept_step": reader.curve.best_step, "stopped": reader.curve.stopped}
        ours[label] = plate_outcomes(reader, plates, profile)
    published = _entry_outcomes(entry, seed)
    ids = sorted(ours["candidate"])
    if set(ids) != set(published["learned-reader"]):
        return {**record, "paired": False, "mismatch": {"ours": len(ids), "published": len(published["learned-reader"])}}
    widths = [ours["candidate"][i][1] for i in ids]
    readable = [i for i in ids if ours["candidate"][i][1] >= FROM_PX]

    def union(reader: dict[str, tuple[int, int]]) -> list[int]:
        """Per plate: read by a published chain other than learned-reader, by learned-reader-psf or by ``reader``."""
        return [int(bool(reader[i][0] or ours["learned-reader-psf"][i][0]
                         or any(p[i][0] for a, p in published.items() if a != "learned-reader" and i in p)))
                for i in ids]

    def pick(values: list[int]) -> list[int]:
        return [v for v, i in zip(values, ids) if ours["candidate"][i][1] >= FROM_PX]

    long_fit = [int(published["learned-reader"][i][0]) for i in ids]
    short_fit = [int(ours["candidate"][i][0]) for i in ids]
    with_long, with_short = union(published["learned-reader"]), union(ours["candidate"])
    record.update({
        "paired": True, "n_plates": len(ids), "n_from_32px": len(readable),
        "readers": {label: {"bins": _bins(values, widths), f"from_{FROM_PX}px": round(float(np.mean(pick(values))), 4)}
                    for label, values in (("candidate", short_fit), ("learned-reader (published fit)", long_fit),
                                          ("ensemble with the candidate", with_short),
                                          ("ensemble with the published fit", with_long))},
        "paired_from_32px": {"candidate - published fit": _compare(pick(short_fit), pick(long_fit)),
                             "ensemble: candidate - published fit": _compare(pick(with_short), pick(with_long))},
    })
    return record


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--lens", action="append", default=None, help="lens (repeatable; default: %s)" % ", ".join(LENSES))
    parser.add_argument("--steps", type=int, default=600, help="the candidate schedule's steps (default 600)")
    parser.add_argument("--lr", type=float, default=BUDGETS["quick"].lr, help="its peak learning rate")
    parser.add_argument("--out", type=Path, default=OUT)
    args = parser.parse_args(argv)
    budget = candidate(args.steps, args.lr)
    study: dict[str, Any] = json.loads(args.out.read_text()) if args.out.exists() else {}
    study.update({"commit": git_commit(), "packages": package_versions(), "threads": torch.get_num_threads(),
                  "seed": 0, "pooled_from_px": FROM_PX,
                  "command": "python -m benchmark.studies.reader_schedule_study " + " ".join(sys.argv[1:] if argv is None else argv)})
    study.setdefault("lenses", {})
    for name in args.lens or list(LENSES):
        t0 = time.perf_counter()
        record = measure_lens(name, budget)
        record.update({"budget": budget.to_dict(), "quick_budget_at_study": BUDGETS["quick"].to_dict(), "seconds": round(time.perf_counter() - t0, 1),
                       "load_average": [round(x, 2) for x in os.getloadavg()]})
        study["lenses"].setdefault(name, {})[label(budget)] = record
        if record["paired"]:
            c = record["paired_from_32px"]
            print(f"{name}, {label(budget)}: fit {record['fit']['fit_s']} s; candidate - published fit "
                  f"{c['candidate - published fit']['difference_pt']:+.1f} pt "
                  f"[{c['candidate - published fit']['low_pt']:+.1f}, {c['candidate - published fit']['high_pt']:+.1f}]; "
                  f"in the ensemble {c['ensemble: candidate - published fit']['difference_pt']:+.1f} pt", flush=True)
        else:
            print(f"{name}: plate ids do not match the entry's; not paired", flush=True)
        args.out.write_text(json.dumps(study, indent=1) + "\n")
    print(f"wrote {args.out}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
