"""A fresh run's attackers against the published entry's, paired per plate and per scene:
``python -m benchmark.studies.run_pairing_study --run runs/<dir> [--run ...] [--lens gp ...]``.

For each lens of the run that has a published quick entry, at one seed (default 0): the run's rows and the
entry's rows of that seed, each reduced to its ensemble (``benchmark.results.ensemble``: a plate read by any
reader chain; a scene at its best restorer). The run must have made the same plates and scenes (the ids
agree, which proves the pairing; a mismatch is reported, not paired).

- Plates: per width bin (``WIDTH_BINS_PX``) both ensembles' accuracies (Wilson 95 %), with the attack gap
  of the run's ensemble against the ideal observer's ceiling (the tighter one where
  ``leaderboard/studies/ideal_observer.json`` holds it); pooled from 32 px, the paired bootstrap
  difference, and the plates each of the run's chains alone read among those the entry's ensemble missed.
- Scenes: the ensemble PSNR of both, and the paired per-scene difference (bootstrap); the run's restorers'
  mean PSNR on the same scenes.
- Costs: each attacker's fit seconds (and the cascade's), as its row measured them; the run's command and
  wall seconds; the load average when the study ran (the run's own load is not recorded).
- Against an earlier run of the lens (``--baseline``): the same paired comparisons, run against run.
- Chains: what each chain of the run decides and its removal effect (``benchmark.results.ensemble_choice``)
  and the run's commit and date. Once the record holds runs of all five ``PRIVACY_LENSES`` (``--run`` is
  repeatable), the rule's proposal on them (``proposal``): the chains it keeps and drops, and what dropping
  all of the latter at once costs each run's ensemble. ``benchmark.runner.defaults.RUN_PROPOSAL`` is that.

Writes ``leaderboard/studies/run_pairing.json`` (merged per lens).
"""

from __future__ import annotations

import argparse
import json
import os
from collections.abc import Sequence
from pathlib import Path
from typing import Any

import numpy as np

from benchmark.results import stats
from benchmark.results.attack_gap import attack_gaps, gap_curves
from benchmark.results.ensemble import plate_ensemble, seed_plates, seed_scene_names, seed_scenes
from benchmark.results.ensemble_choice import (
    ChainEffect, Outcomes, complete_ensemble, ensemble_values, proposed_ensemble, removal_effects, strongest_restorer,
    with_restorers)
from benchmark.results.entries import Entry, entry_name, read_entry
from benchmark.results.plate_scoring import WIDTH_BINS_PX
from benchmark.results import schema
from benchmark.results.schema import Results, Row
from benchmark.store.provenance import git_commit

__all__ = ["main", "pair_lens", "read_results"]

ROOT = Path(__file__).resolve().parents[2]
LEADERBOARD = ROOT / "leaderboard"
OUT = LEADERBOARD / "studies" / "run_pairing.json"
FROM_PX = 32
PRIVACY_LENSES = ("ideal", "defocus", "gp", "os", "os-d-1000")  # the lenses the ensemble is chosen on
SECONDS = ("fit_s", "cascade_s")  # what a row measures of its own attacker's cost


def _compare(a: np.ndarray, b: np.ndarray, direction: str = "greater") -> dict[str, Any]:
    c = stats.paired_bootstrap(a.astype(float), b.astype(float))
    return {"difference": round(c.difference, 4), "low": round(c.low, 4), "high": round(c.high, 4),
            "p_value": c.p_value, "verdict": stats.verdict(c, direction).label, "n": c.n}


def _plates(run_rows: list[Row], entry_rows: list[Row], seed: int, study: dict[str, Any] | None, lens: str,
            spec: dict[str, Any] | None) -> dict[str, Any]:
    ours, theirs = seed_plates(run_rows, seed, readable_only=False), seed_plates(entry_rows, seed, readable_only=False)
    if ours is None or theirs is None:
        return {"paired": False, "why": "no per-plate units in " + ("the run" if ours is None else "the entry")}
    if set(ours.names) != set(theirs.names):
        return {"paired": False, "why": "plate ids differ", "run": len(ours.names), "entry": len(theirs.names),
                "common": len(set(ours.names) & set(theirs.names))}
    order = [theirs.names.index(n) for n in ours.names]
    entry_read = theirs.ensemble[order]
    widths = ours.widths if ours.widths is not None else np.zeros(len(ours.names))
    readable = widths >= FROM_PX
    out: dict[str, Any] = {"paired": True, "n_plates": len(ours.names), f"n_from_{FROM_PX}px": int(readable.sum())}
    out[f"from_{FROM_PX}px"] = {"run": round(float(ours.ensemble[readable].mean()), 4),
                                "entry": round(float(entry_read[readable].mean()), 4),
                                "run - entry": _compare(ours.ensemble[readable], entry_read[readable])}
    missed = readable & ~entry_read
    out["chains_on_plates_the_entry_missed"] = {
        chain: int((ours.read[i] & missed).sum()) for i, chain in enumerate(ours.chains)}
    out["entry_missed"] = int(missed.sum())
    curve, fallback = gap_curves(study, lens, spec)
    ensemble = plate_ensemble(run_rows)
    gaps = {} if curve is None or ensemble is None else {
        f"{g.low_px:g}": {"ceiling": round(g.ceiling, 4), "kind": g.ceiling_kind, "gap": round(g.gap, 4)}
        for g in attack_gaps(ensemble, curve, fallback)}
    bins = {}
    edges = [*WIDTH_BINS_PX, np.inf]
    for low, high in zip(edges[:-1], edges[1:]):
        inside = (widths >= low) & (widths < high)
        if inside.any():
            n = int(inside.sum())
            run_hits, entry_hits = int(ours.ensemble[inside].sum()), int(entry_read[inside].sum())
            bins[f"{low:g}"] = {"n": n, "run": round(run_hits / n, 4), "run_interval": stats.wilson_interval(run_hits, n),
                                "entry": round(entry_hits / n, 4), **({"gap": gaps[f"{low:g}"]} if f"{low:g}" in gaps else {})}
    out["bins"] = bins
    return out


def _scenes(run_rows: list[Row], entry_rows: list[Row], seed: int) -> dict[str, Any]:
    ours, theirs = seed_scenes(run_rows, seed), seed_scenes(entry_rows, seed)
    if ours is None or theirs is None:
        return {"paired": False, "why": "no per-scene units"}
    names_ours, names_theirs = seed_scene_names(run_rows, seed), seed_scene_names(entry_rows, seed)
    if set(names_ours) != set(names_theirs):
        return {"paired": False, "why": "scene ids differ"}
    order = [names_theirs.index(n) for n in names_ours]
    best_ours, best_theirs = ours[1].max(axis=1), theirs[1].max(axis=1)[order]
    return {"paired": True, "n_scenes": len(names_ours), "run_db": round(float(best_ours.mean()), 3),
            "entry_db": round(float(best_theirs.mean()), 3), "run - entry": _compare(best_ours, best_theirs),
            "run_restorers_db": {r: round(float(v), 3) for r, v in zip(ours[0], ours[1].mean(axis=0))}}


def _as_entry(rows: list[Row], lens: str) -> Entry:
    """A run's rows of one lens as an entry, the form ``benchmark.results.ensemble_choice`` measures."""
    return Entry(lens=lens, profile="quick", scenes="synthetic", seeds=sorted({r.seed for r in rows}),
                 profile_values={}, coefficients_um=None, lens_spec=None, rows=rows)


def chain_effects(rows: list[Row], lens: str) -> dict[str, dict[str, Any]]:
    """Per chain of the run's rows of one lens and seed: what it decides and its removal effect
    (``benchmark.results.ensemble_choice``), and whether the rule keeps it for this lens (``matters``)."""
    return {e.attack: {"kind": e.kind, "first": e.first, "only": e.only, "best_scenes": e.best_scenes,
                       "plate_points": round(e.plate_points, 3), "psnr_db": round(e.psnr_db, 4), "matters": e.matters}
            for e in removal_effects([_as_entry(rows, lens)])}


def pair_lens(run_rows: list[Row], lens: str, seed: int, study: dict[str, Any] | None) -> dict[str, Any]:
    """The study's record of `lens` (module docs)."""
    entry = read_entry(LEADERBOARD / "entries" / entry_name(lens, "quick", "synthetic"))
    ours = [r for r in run_rows if r.lens == lens and r.seed == seed]
    theirs = [r for r in entry.rows if r.seed == seed]
    return {"plates": _plates(ours, theirs, seed, study, lens, entry.lens_spec),
            "scenes": _scenes(ours, theirs, seed),
            "chain_effects": chain_effects(ours, lens),
            "run_provenance": sorted({f"{r.provenance.get('git_commit', '?')[:12]} {str(r.provenance.get('date', '?'))[:10]}"
                                      for r in ours if r.provenance}),
            "seconds": {r.attack: {k: round(float(v), 1) for k, v in r.metrics.items() if k in SECONDS}
                        for r in ours if r.ok and any(k in r.metrics for k in SECONDS)}}


def against(ours: list[Row], folder: Path, theirs: list[Row], seed: int, study: dict[str, Any] | None,
            lens: str) -> dict[str, Any]:
    """`ours` (one lens and seed of a run) paired against an earlier run's rows of that lens and seed, as
    against the entry: plates from FROM_PX px and the ensemble PSNR (``run`` is ours, ``entry`` the earlier)."""
    spec = read_entry(LEADERBOARD / "entries" / entry_name(lens, "quick", "synthetic")).lens_spec
    plates, scenes = _plates(ours, theirs, seed, study, lens, spec), _scenes(ours, theirs, seed)
    return {"folder": str(folder), "plates_from_px": plates.get(f"from_{FROM_PX}px", plates.get("why")),
            "scenes": {k: v for k, v in scenes.items() if k != "run_restorers_db"}}


def proposal(record: dict[str, Any], runs: dict[str, list[Row]]) -> dict[str, Any]:
    """The rule of ``benchmark.results.ensemble_choice`` applied to the fresh runs' chain effects of the
    privacy lenses (``PRIVACY_LENSES``, as far as the record holds them): the chains it keeps plus the paper's
    ``lpdr`` on the sensor image and after the strongest restorer (``rule``), completed on the runs at hand
    (``complete_ensemble``: chains that decide nothing alone but read plates together, and the restorers the
    reader chains read); and, per lens whose run rows are at hand, what dropping every other chain together
    costs the run's ensemble (plates from every width, points; PSNR, dB)."""
    lenses = [lens for lens in PRIVACY_LENSES if "chain_effects" in record["lenses"].get(lens, {})]
    effects = [ChainEffect(lens, "quick", "synthetic", chain, e["kind"], e["first"], e["only"], e["best_scenes"],
                           e["plate_points"], e["psnr_db"])
               for lens in lenses for chain, e in record["lenses"][lens]["chain_effects"].items()]
    rule = proposed_ensemble(effects)
    at_hand = {lens: rows for lens, rows in runs.items() if lens in lenses}
    outcomes = [Outcomes.of(rows, lens, int(record.get("seed", 0))) for lens, rows in at_hand.items()]
    chains, added = complete_ensemble(rule, outcomes)
    rule_alone = with_restorers(rule, outcomes)

    def removal(run: Entry, kept: Sequence[str]) -> dict[str, float | None]:
        (plates_all, psnr_all), (plates_kept, psnr_kept) = ensemble_values(run), ensemble_values(run, set(kept))
        return {"plate_points": None if plates_all is None else round(plates_all - (plates_kept or 0.0), 3),
                "psnr_db": None if psnr_all is None else round(psnr_all - (psnr_kept or 0.0), 4)}

    runs_at_hand = {lens: _as_entry(rows, lens) for lens, rows in at_hand.items()}
    return {"lenses": lenses, "strongest_restorer": strongest_restorer(effects), "rule": list(rule),
            "rule_joint_removal": {lens: removal(run, rule_alone) for lens, run in runs_at_hand.items()},
            "added_jointly": list(added), "chains": list(chains),
            "dropped": sorted({e.attack for e in effects} - set(chains)),
            "joint_removal": {lens: removal(run, chains) for lens, run in runs_at_hand.items()}}


def read_results(path: Path) -> Results:
    """A run's results: its folder (``results.json`` in it) or a results file, plain or gzipped (``.json.gz``,
    as ``leaderboard/studies/cross_product`` keeps the cross-product runs the ensemble is chosen on)."""
    file = path / "results.json" if path.is_dir() else path
    if not file.is_file():
        raise SystemExit(f"{path}: neither a run folder holding results.json nor a results file")
    try:
        return schema.read_results(file)
    except ValueError as e:
        raise SystemExit(f"not a run's results: {e}") from e


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--run", type=Path, action="append", required=True,
                        help="a run's folder (its results.json) or a results file (.json, .json.gz); repeatable")
    parser.add_argument("--lens", action="append", default=None, help="lens (repeatable; default: every lens of the runs)")
    parser.add_argument("--seed", type=int, default=0)
    parser.add_argument("--out", type=Path, default=OUT)
    parser.add_argument("--baseline", type=Path, action="append", default=[],
                        help="an earlier run's folder: each lens it holds is also paired against it, the same way "
                             "(`against_baseline`: what changed between two runs of one lens); repeatable")
    args = parser.parse_args(argv)
    baselines = {}
    for folder in args.baseline:
        rows = read_results(folder).rows
        baselines.update({lens: (folder, [r for r in rows if r.lens == lens and r.seed == args.seed])
                          for lens in {r.lens for r in rows}})
    study_path = LEADERBOARD / "studies" / "ideal_observer.json"
    observer = json.loads(study_path.read_text()) if study_path.exists() else None
    record: dict[str, Any] = json.loads(args.out.read_text()) if args.out.exists() else {}
    record.update({"commit": git_commit(), "seed": args.seed, "load_average_at_study": [round(x, 2) for x in os.getloadavg()],
                   "pooled_from_px": FROM_PX})
    record.setdefault("lenses", {})
    runs: dict[str, list[Row]] = {}
    for folder in args.run:
        results = read_results(folder)
        for lens in args.lens or sorted({r.lens for r in results.rows}):
            if not (LEADERBOARD / "entries" / entry_name(lens, "quick", "synthetic")).exists():
                print(f"{lens}: no published quick entry; skipped")
                continue
            if not any(r.lens == lens for r in results.rows):
                continue  # a lens named with --lens that this run does not hold (another --run does)
            if lens in runs and lens not in PRIVACY_LENSES:
                continue  # a reference lens (sharp) every run holds: the first run's
            runs[lens] = [r for r in results.rows if r.lens == lens and r.seed == args.seed]
            pairing = pair_lens(results.rows, lens, args.seed, observer)
            pairing["run"] = {"folder": str(folder), "command": results.meta.get("command"),
                              "wall_s": results.meta.get("wall_s")}
            if lens in baselines:
                pairing["against_baseline"] = against(runs[lens], *baselines[lens], args.seed, observer, lens)
            record["lenses"][lens] = pairing
            p, s = pairing["plates"], pairing["scenes"]
            line = f"{lens}: "
            if p["paired"]:
                c = p[f"from_{FROM_PX}px"]
                line += f"plates from {FROM_PX} px {100 * c['entry']:.1f} -> {100 * c['run']:.1f} % ({c['run - entry']['verdict']})"
            if s["paired"]:
                line += f"; ensemble PSNR {s['entry_db']:.2f} -> {s['run_db']:.2f} dB ({s['run - entry']['verdict']})"
            print(line)
    missing = [lens for lens in PRIVACY_LENSES if "chain_effects" not in record["lenses"].get(lens, {})]
    if missing:  # the rule chooses on all five privacy lenses or not at all
        record.pop("proposal", None)
        print(f"no proposal: the record holds no run of {', '.join(missing)}")
    else:
        record["proposal"] = proposal(record, runs)
        print(f"the rule on the runs of {', '.join(record['proposal']['lenses'])}: keeps "
              f"{', '.join(record['proposal']['chains'])}; drops {', '.join(record['proposal']['dropped'])}")
    args.out.parent.mkdir(parents=True, exist_ok=True)
    args.out.write_text(json.dumps(record, indent=1, default=float) + "\n")
    print(f"wrote {args.out}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
