"""The ideal-observer study: the ceiling curve and W_5% of every lens of the quick leaderboard.

For each lens (built from its entry's `lens_spec`, the co-designed coefficients included, never
retrained): plate and per-character ceilings at every width of `WIDTHS_PX` for T = 1 and 30 frames,
the certified widths W_5%, and the seconds it took. For `DEPTH_LENSES` the same curve once more with
the PSF at each width's own object distance (`lenses.depth.plate_distance_m`), to show whether one
object plane suffices. Each lens's record keeps the lens spec it was computed for (`lens_spec`), so
the leaderboard shows a ceiling only beside an entry of that very lens (benchmark.results.observer.published).
With `--marginal`, each lens's record also holds the tighter ceiling (`record["marginal"]`:
benchmark.results.observer.marginal, the ideal observer not told the nuisances of a `NuisancePrior`),
per width bin [w_k, w_{k+1}) of the same grid, with its seconds, load, prior and precision, and its
convergence against the number of nuisance points at one width bin (`convergence`).
Writes leaderboard/studies/ideal_observer.json and its chart leaderboard/charts/ideal_observer.png
(benchmark.results.charts.ideal_observer_chart, re-rendered by `python -m benchmark report` with the readers on it).
"""

from __future__ import annotations

import dataclasses
import json
import logging
import os
import time
from pathlib import Path
from typing import Any

from benchmark.results.observer.ceiling import CeilingCurve, PlateModel, Precision, ceiling_curves, certified_width
from benchmark.results.observer.marginal import bin_highs, convergence, marginal_ceiling_curves
from benchmark.results.observer.nuisance import NuisancePrior
from lenses import Lens, parse_spec

WIDTHS_PX = (4, 6, 8, 12, 16, 24, 32, 48, 64, 96, 128, 160)
FRAMES = (1, 30)
DEPTH_LENSES = ("ideal", "defocus", "os-d-1000", "gp")
EPS = 0.05
REPO = Path(__file__).resolve().parents[2]

log = logging.getLogger(__name__)


def quick_lens_specs(entries_dir: Path = REPO / "leaderboard" / "entries") -> dict[str, dict]:
    """The stored lens spec of every lens of the quick synthetic leaderboard (name -> spec dict)."""
    found = {}
    for path in sorted(entries_dir.glob("*__quick__synthetic.json")):
        entry = json.loads(path.read_text(encoding="utf-8"))
        if entry.get("lens_spec") is not None:  # the `sharp` reference has no lens
            found[entry["lens"]] = entry["lens_spec"]
    if not found:
        raise FileNotFoundError(f"no quick leaderboard entry with a lens_spec under {entries_dir}")
    return found


def quick_lenses(entries_dir: Path = REPO / "leaderboard" / "entries") -> dict[str, Lens]:
    """Every lens of the quick synthetic leaderboard, from its entry's stored spec (name -> Lens)."""
    return {name: Lens(parse_spec(spec, source=f"{entries_dir}/{name}__quick__synthetic.json"))
            for name, spec in quick_lens_specs(entries_dir).items()}


def summary(curve: CeilingCurve) -> dict:
    """W_5% (plate, per character), the ceilings at 32 px and the whole curve, JSON-ready."""
    at32 = list(curve.widths_px).index(32) if 32 in curve.widths_px else None
    return {"w5_plate_px": certified_width(curve, EPS), "w5_char_px": certified_width(curve, EPS, per_character=True),
            "plate_ceiling_w32": None if at32 is None else float(curve.plate_ceiling[at32]),
            "char_ceiling_w32": None if at32 is None else float(curve.char_ceiling[at32]),
            "curve": curve.to_dict()}


def _load_average() -> float:
    """The machine's 1-minute load average (`uptime`), recorded beside every timing."""
    return round(os.getloadavg()[0], 2)


def _timed_curves(lens: Lens, widths_px: tuple[int, ...], frames: tuple[int, ...], seed: int,
                  precision: Precision, at_own_distance: bool) -> dict:
    """The summaries of one ceiling computation (t1, t30, ...) with its wall seconds, the machine's load
    before and after, the widths and the precision it ran with."""
    load_before, t0 = _load_average(), time.perf_counter()
    curves = ceiling_curves(lens, widths_px, frames, seed=seed, precision=precision, at_own_distance=at_own_distance)
    return {"seconds": time.perf_counter() - t0, "load_average": [load_before, _load_average()],
            "widths_px": list(widths_px), "precision": dataclasses.asdict(precision),
            **{f"t{c.frames}": summary(c) for c in curves}}


def _timed_marginal(lens: Lens, widths_px: tuple[int, ...], frames: tuple[int, ...], seed: int, precision: Precision,
                    prior: NuisancePrior, convergence_width_px: int | None,
                    convergence_points: tuple[int, ...] = (1, 2, 4, 8, 16, 32)) -> dict:
    """The tighter ceiling's summaries (t1, ...) per width bin, with its seconds, load before and after,
    widths, bin ends, prior and precision, and (convergence_width_px given) its convergence at that bin."""
    load_before, t0 = _load_average(), time.perf_counter()
    highs = bin_highs(list(widths_px))
    curves = marginal_ceiling_curves(lens, widths_px, frames, prior=prior, seed=seed, precision=precision,
                                     width_high_px=highs, pair=(0, 1))
    out: dict[str, Any] = {"seconds": time.perf_counter() - t0, "load_average": [load_before, _load_average()],
                           "widths_px": list(widths_px), "width_high_px": highs,
                           "precision": dataclasses.asdict(precision), "prior": dataclasses.asdict(prior),
                           **{f"t{c.frames}": summary(c) for c in curves}}
    if convergence_width_px is not None:
        k = list(widths_px).index(convergence_width_px)
        t1 = time.perf_counter()
        out["convergence"] = convergence(lens, convergence_width_px, out["width_high_px"][k], convergence_points, prior,
                                         seed=seed)
        out["convergence"]["seconds"] = time.perf_counter() - t1
    return out


def run_study(out_json: Path = REPO / "leaderboard" / "studies" / "ideal_observer.json",
              out_png: Path | None = REPO / "leaderboard" / "charts" / "ideal_observer.png",
              names: tuple[str, ...] | None = None, widths_px: tuple[int, ...] = WIDTHS_PX,
              frames: tuple[int, ...] = FRAMES, depth_lenses: tuple[str, ...] = DEPTH_LENSES, seed: int = 0,
              precision: Precision = Precision(max_plates=40), depth_only: bool = False,
              note: str | None = None, marginal: NuisancePrior | None = None, marginal_only: bool = False,
              convergence_width_px: int | None = None) -> dict:
    """Compute the study (module docstring) for `names` (default: all quick lenses) and merge it into
    `out_json`: the lenses computed now replace their old records, every other lens is kept as it was.

    depth_only: compute only the curve at each width's own distance (`at_own_distance`) for lenses
    whose flat curve `out_json` already holds for the same lens spec (else a ValueError names them).
    Each lens records its seconds, the load average before and after, its widths and precision, and
    `note` (e.g. why its grid is reduced). The json is written after every lens (an interrupted run
    keeps what it finished); the chart (`out_png`, None: none) once at the end.

    marginal: also compute the tighter ceiling under this prior (`record["marginal"]`, T = 1 only),
    with its convergence at `convergence_width_px` when given; marginal_only: only that, for lenses whose
    flat curve `out_json` already holds for the same spec (as depth_only).
    """
    from benchmark.results.observer.published import same_lens
    specs = quick_lens_specs()
    lenses_by_name = quick_lenses()
    names = names or tuple(lenses_by_name)
    unknown = [n for n in names if n not in lenses_by_name]
    if unknown:
        raise ValueError(f"lenses {unknown} are not on the quick leaderboard; valid: {sorted(lenses_by_name)}")
    model = json.loads(json.dumps(PlateModel().__dict__))  # as stored: tuples become lists
    record: dict = (json.loads(out_json.read_text(encoding="utf-8")) if out_json.is_file()
                    else {"eps": EPS, "seed": seed, "plate_model": model, "lenses": {}})
    if record.get("eps") != EPS or record.get("seed") != seed or record.get("plate_model") != model:
        raise ValueError(f"{out_json} was computed with another eps, seed or plate model; merge into a new file")
    if marginal_only and marginal is None:
        raise ValueError("marginal_only needs a nuisance prior (marginal=NuisancePrior(...))")
    if depth_only or marginal_only:
        lacking = [n for n in names if n not in record["lenses"] or not same_lens(record["lenses"][n]["lens_spec"],
                                                                                  specs[n])]
        if lacking:
            raise ValueError(f"depth_only and marginal_only need the flat curve of {lacking} in {out_json}; "
                             "compute it first")
    for name in names:
        lens = lenses_by_name[name]
        if depth_only or marginal_only:
            entry = record["lenses"][name]
        else:
            # The spec travels with the curve: the leaderboard shows it only for entries of the same lens.
            entry = {"lens_spec": specs[name], **_timed_curves(lens, widths_px, frames, seed, precision, False)}
            if note:
                entry["note"] = note
        if marginal is not None:
            entry["marginal"] = _timed_marginal(lens, widths_px, (1,), seed, precision, marginal, convergence_width_px)
            if note:
                entry["marginal"]["note"] = note
        if (name in depth_lenses and not marginal_only) or depth_only:
            entry["at_own_distance"] = _timed_curves(lens, widths_px, frames, seed, precision, True)
            if note:
                entry["at_own_distance"]["note"] = note
        record["lenses"][name] = entry
        record["not_computed"] = sorted(set(lenses_by_name) - set(record["lenses"]))
        log.info("%s: %.0f s (load %s), W5 plate T=1 %s px", name, entry["seconds"], entry.get("load_average"),
                 entry["t1"]["w5_plate_px"])
        out_json.parent.mkdir(parents=True, exist_ok=True)
        out_json.write_text(json.dumps(record, indent=1) + "\n", encoding="utf-8")
    if out_png is not None:
        write_chart(record, out_png)
    return record


def merge_study(out_json: Path, part_json: Path, names: tuple[str, ...]) -> dict:
    """Copy the records of lenses `names` from `part_json` (a study computed apart, e.g. one lens per
    process) into `out_json`, keeping every other lens of `out_json`; returns the merged record.
    Both must share eps, seed and plate model (else a ValueError)."""
    out, part = (json.loads(Path(p).read_text(encoding="utf-8")) for p in (out_json, part_json))
    if any(out.get(k) != part.get(k) for k in ("eps", "seed", "plate_model")):
        raise ValueError(f"{part_json} and {out_json} differ in eps, seed or plate model; they cannot be merged")
    missing = [n for n in names if n not in part["lenses"]]
    if missing:
        raise ValueError(f"{part_json} has no record of {missing}; it has {sorted(part['lenses'])}")
    out["lenses"].update({n: part["lenses"][n] for n in names})
    out["not_computed"] = sorted(set(quick_lens_specs()) - set(out["lenses"]))
    Path(out_json).write_text(json.dumps(out, indent=1) + "\n", encoding="utf-8")
    return out


def write_chart(record: dict, path: Path) -> Path:
    """The study's chart (benchmark.results.charts.ideal_observer_chart) with the published entries' readers on it."""
    from benchmark.results.charts.ideal_observer_chart import write_ideal_observer_chart
    from benchmark.results.entries import load_entries
    return write_ideal_observer_chart(record, load_entries(path.parent.parent), path)


def main(argv: list[str] | None = None) -> dict:
    """`python -m benchmark.studies.observer_study --lens NAME ... [--widths 4 6 ...] [--max-plates N] [--depth-only]`."""
    import argparse
    parser = argparse.ArgumentParser(prog="python -m benchmark.studies.observer_study", description=__doc__.split("\n")[0])
    parser.add_argument("--lens", action="append", help="a quick-leaderboard lens (repeat; default: all)")
    parser.add_argument("--widths", type=int, nargs="+", default=list(WIDTHS_PX), help="plate widths in px")
    parser.add_argument("--max-plates", type=int, default=40, help="most plate draws per width")
    parser.add_argument("--depth-only", action="store_true", help="only the curve at each width's own distance")
    parser.add_argument("--note", help="stored with each lens computed (e.g. why the grid is reduced)")
    parser.add_argument("--no-chart", action="store_true", help="do not redraw the chart")
    parser.add_argument("--marginal", action="store_true", help="also the tighter (marginalised) ceiling")
    parser.add_argument("--marginal-only", action="store_true", help="only the tighter ceiling (flat curve kept)")
    parser.add_argument("--position", default="continuous", help="position prior: known, pixel-grid, continuous")
    parser.add_argument("--width", default="continuous", help="width prior: known, pixel-grid, continuous")
    parser.add_argument("--exposure", type=float, nargs=2, default=[0.85, 1.05], help="exposure prior (low high)")
    parser.add_argument("--points", type=int, default=32, help="nuisance points per likelihood")
    parser.add_argument("--exhaustive", action="store_true", help="every point of a discrete prior")
    parser.add_argument("--convergence-width", type=int, help="width bin whose convergence against M is stored")
    parser.add_argument("--out", type=Path, default=REPO / "leaderboard" / "studies" / "ideal_observer.json",
                        help="the study json to merge into")
    args = parser.parse_args(argv)
    logging.basicConfig(level=logging.INFO, format="%(asctime)s %(name)s %(message)s")
    prior = (NuisancePrior(args.position, args.width, tuple(args.exposure), args.points, args.exhaustive)
             if args.marginal or args.marginal_only else None)
    return run_study(out_json=args.out,
                     out_png=None if args.no_chart else REPO / "leaderboard" / "charts" / "ideal_observer.png",
                     names=tuple(args.lens) if args.lens else None, widths_px=tuple(args.widths),
                     precision=Precision(max_plates=args.max_plates), depth_only=args.depth_only, note=args.note,
                     marginal=prior, marginal_only=args.marginal_only, convergence_width_px=args.convergence_width)


if __name__ == "__main__":
    main()
