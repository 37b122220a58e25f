"""The learned reader's starts compared on the registry's lenses, paired per plate: ``python -m benchmark.studies.reader_family_study``.

For each lens (default: ideal, defocus, gp, os, os-d-1000) it rebuilds the lens of the published quick
entry at seed 0 (its ``lens_spec``) and draws an evaluation set of plates through it (``EVAL_PLATES``
per width bin of ``EVAL_WIDTHS_PX``, true boxes, from ``EVAL_SEED``: not the plates any fit selects its
weights on). On the same plates it reads with
- ``sharp``: the sharp-plate start, zero-shot (what every per-lens fit started from before the family);
- ``family``: the family pre-training, zero-shot on a lens it was not trained on as such;
- ``family+fit``: what a quick run fits now (``LearnedReader`` with the quick budget: the family start
  evaluated on the lens and fine-tuned for ``FAMILY_FINE_TUNE["quick"]``), timed;
- ``shipped-fit`` (gp only, when the package still ships it): the gp fit of the sharp start with the
  2400-step budget, what the published quick gp entry read with.
Each is scored per plate (single view on the true box: the crops the fits train and select on); the
record holds per-bin accuracies with Wilson intervals and paired comparisons over every plate of 32 px
and wider (paired bootstrap of the per-plate outcomes, ``benchmark.results.stats``). Writes
``leaderboard/studies/reader_family.json``.
"""

from __future__ import annotations

import argparse
import dataclasses
import json
import os
import time
from pathlib import Path
from typing import Any

import numpy as np
import torch

from attacks.base import AttackBudget, FitContext
from attacks.readers.learned_reader import (
    BUDGETS, FAMILY_FINE_TUNE, LearnedReader, family_key, pretrained_key, unpack_weights)
from attacks.readers.plates.plate_sim import PlateBatch, psf_radius_px
from attacks.training.plate_reader_training import EVAL_WIDTHS_PX, held_out_set
from attacks.training.shipped_weights import SHIPPED_DIR, find_shipped, read_checked
from benchmark.results import stats
from benchmark.store.cache import ArtifactCache, cache_root
from benchmark.store.provenance import git_commit, package_versions
from common.plate_render import PLATE_FORMAT
from lenses.lens import Lens
from lenses.spec import parse_spec

__all__ = ["EVAL_PLATES", "EVAL_SEED", "main", "measure_lens"]

ROOT = Path(__file__).resolve().parents[2]
ENTRIES = ROOT / "leaderboard" / "entries"
OUT = ROOT / "leaderboard" / "studies" / "reader_family.json"
LENSES = ("ideal", "defocus", "gp", "os", "os-d-1000")
EVAL_PLATES = 100     # plates per width bin
EVAL_SEED = 424242    # the evaluation plates' draw (the fits' own held-out sets use the fit seed)
FROM_PX = 32          # the paired comparisons pool every plate at least this wide


def correct(net: torch.nn.Module, batch: PlateBatch) -> list[int]:
    """Per plate of `batch`, 1 when `net` reads every slot right (single view, true box), else 0."""
    net.eval()
    with torch.no_grad():
        logits = net(batch.crops)
    predicted = torch.stack([slot.argmax(dim=1) for slot in logits], dim=1)
    return [int(v) for v in (predicted == batch.labels).all(dim=1)]


def _bins(outcomes: dict[int, list[int]]) -> dict[str, Any]:
    out = {}
    for width, hits in outcomes.items():
        low, high = stats.wilson_interval(sum(hits), len(hits))
        out[str(width)] = {"accuracy": round(float(np.mean(hits)), 4), "low": round(low, 4), "high": round(high, 4),
                           "n": len(hits)}
    return out


def _pooled(outcomes: dict[int, list[int]]) -> list[int]:
    return [h for w, hits in outcomes.items() if w >= FROM_PX for h in hits]


def _compare(a: list[int], b: list[int]) -> dict[str, Any]:
    c = stats.paired_bootstrap(a, b)
    return {"difference_pt": round(100 * c.difference, 2), "low_pt": round(100 * c.low, 2),
            "high_pt": round(100 * c.high, 2), "p_value": c.p_value, "verdict": stats.verdict(c, "greater").label,
            "n": c.n}


def _net(data: bytes) -> torch.nn.Module:
    net = LearnedReader.build(PLATE_FORMAT, 0)
    unpack_weights(net, data)
    return net


def measure_lens(name: str, seed: int = 0) -> dict[str, Any]:
    """The study's record for one lens (module docs)."""
    entry = json.loads((ENTRIES / f"{name}__quick__synthetic.json").read_text())
    spec = entry["lens_spec"]  # the lens of seed 0
    lens = Lens(parse_spec(spec, f"{name} entry"))
    psf = lens.psf().detach()
    spread, half = psf_radius_px(psf), psf.shape[-1] // 2

    def camera(x: torch.Tensor, generator: torch.Generator) -> torch.Tensor:
        with torch.no_grad():
            return lens(x, generator=generator)

    t0 = time.perf_counter()
    plates = held_out_set(camera, dataclasses.replace(BUDGETS["quick"], eval_plates=EVAL_PLATES), spread, half,
                          PLATE_FORMAT, EVAL_SEED)
    simulate_s = time.perf_counter() - t0
    readers: dict[str, torch.nn.Module] = {}
    sharp = find_shipped(LearnedReader.name, pretrained_key(PLATE_FORMAT))
    family = find_shipped(LearnedReader.name, family_key(PLATE_FORMAT))
    if sharp is None or family is None:
        raise SystemExit("error: the study compares the shipped sharp and family starts; the package lacks "
                         + ("learned-reader-sharp-s0" if sharp is None else "learned-reader-family-s0"))
    readers["sharp"], readers["family"] = _net(sharp.data), _net(family.data)
    seconds: dict[str, float] = {}
    fitted = LearnedReader(use_shipped_fit=False)
    t0 = time.perf_counter()
    # The run's own cache of learned-reader fits: ``ship-lens NAME --reader-only`` then ships this fit.
    artifacts = ArtifactCache(cache_root() / "attacks")
    report = fitted.fit(FitContext(lens=lens, seed=seed, budget=AttackBudget(profile="quick"), artifacts=artifacts))
    seconds["family+fit"] = round(time.perf_counter() - t0, 1)
    assert fitted.net is not None and fitted.curve is not None
    readers["family+fit"] = fitted.net.cpu()
    shipped_fit = SHIPPED_DIR / f"learned-reader-{name}-quick-s0.safetensors"
    if shipped_fit.exists():
        provenance = json.loads(shipped_fit.with_suffix(".json").read_text())
        if "family" not in provenance["key"].get("start", {}):
            readers["shipped-fit"] = _net(read_checked(shipped_fit, provenance["size"], provenance["sha256"],
                                                       "the shipped learned-reader fit"))
    outcomes = {r: {w: correct(net, b) for w, b in plates.items()} for r, net in readers.items()}
    pooled = {r: _pooled(o) for r, o in outcomes.items()}
    record: dict[str, Any] = {
        "lens_spec": spec, "spread_px": round(spread, 3), "simulate_s": round(simulate_s, 1),
        "readers": {r: {"bins": _bins(o), f"from_{FROM_PX}px": round(float(np.mean(pooled[r])), 4)}
                    for r, o in outcomes.items()},
        "fit": {"seconds": seconds["family+fit"], "stage_seconds": {k: round(v, 1) for k, v in report.stage_seconds.items()},
                "trained_here": fitted.trained, "curve": fitted.curve.to_dict(),
                "budget": FAMILY_FINE_TUNE["quick"].to_dict(),
                "kept_start": fitted.curve.best_step == 0},
        "paired": {f"{a} - {b}": _compare(pooled[a], pooled[b]) for a, b in
                   [("family", "sharp"), ("family+fit", "family")]
                   + [(x, "shipped-fit") for x in ("family", "family+fit") if "shipped-fit" in readers]},
    }
    return record


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--lens", action="append", default=None, help="lens (repeatable; default: %s)" % ", ".join(LENSES))
    parser.add_argument("--out", type=Path, default=OUT)
    args = parser.parse_args(argv)
    names = args.lens or list(LENSES)
    study: dict[str, Any] = json.loads(args.out.read_text()) if args.out.exists() else {}
    study.update({"eval": {"plates_per_bin": EVAL_PLATES, "seed": EVAL_SEED, "widths_px": list(EVAL_WIDTHS_PX),
                           "pooled_from_px": FROM_PX, "views": 1},
                  "commit": git_commit(), "packages": package_versions(), "threads": torch.get_num_threads(),
                  "load_average": [round(x, 2) for x in os.getloadavg()]})
    study.setdefault("lenses", {})
    for name in names:
        t0 = time.perf_counter()
        study["lenses"][name] = measure_lens(name)
        study["lenses"][name]["seconds"] = round(time.perf_counter() - t0, 1)
        line = ", ".join(f"{r} {100 * v[f'from_{FROM_PX}px']:.1f} %" for r, v in study["lenses"][name]["readers"].items())
        print(f"{name}: plates from {FROM_PX} px read: {line}; fit {study['lenses'][name]['fit']['seconds']} s")
        args.out.write_text(json.dumps(study, indent=1) + "\n")
    print(f"wrote {args.out}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
