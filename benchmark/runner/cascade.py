"""The cascade: an expensive reader run last, only on the plates no earlier chain of the run read.

The ensemble counts a plate as read when any chain read it, so a reader that costs seconds per plate
changes the ensemble only on the plates the cheap chains missed. As AutoAttack runs its costlier attacks
only on the points the cheaper ones left standing, the run gives a cascade reader (a chain named
``cascade:<reader>``, `CASCADE_PREFIX`) the plate windows that no chain before it read, and of those
only the ones in width bins where the chains before it read under `OPEN_BIN_BELOW` of the plates: only
there can the gap to any ceiling (at most 100 %) exceed 30 points. It reads the widest of them first
(the readable end of the range), at most `plates_per_lens` (a count, not seconds, so the result does not
depend on the machine); the run states how many it was given, how many it read and what that cost.

Its row is a reader row on the sensor image whose per-plate outcomes hold every scored plate: the plates
it was not given count as not read (so its plate accuracy is what it adds, not what it would read alone,
and the ensemble's union is exact: a plate not given to it was read by an earlier chain or lies in a bin
that is already open). Choosing the plates uses the truth, as the ensemble's union does: the cascade is
how the evaluator spends its budget, not something the attacker knows.
"""

from __future__ import annotations

import logging
import time
from collections.abc import Sequence

import numpy as np

from benchmark.results.plate_scoring import WIDTH_BINS_PX, PlateOutcome, score_scene
from benchmark.results.schema import LEARNS, RowError, cascade_name
from benchmark.runner.config import RunConfig
from benchmark.runner.evaluation import Attacked, ReadyReader, Target, plate_records, plate_row, read_plates
from benchmark.runner.isolation import attempt
from benchmark.runner.rows import RowBuilder

__all__ = ["EVERY_PLATE_FROM_PX", "PLATES_PER_LENS", "run_cascade", "wanted_readers"]

log = logging.getLogger(__name__)

OPEN_BIN_BELOW = 0.7  # a bin where the chains before read this share or more is left to them
# Plates a cascade reader is given per lens and seed, by profile: the ideal-observer reader takes about
# 2-3 s a plate on 2 cores (leaderboard/studies/ideal_observer_beam.json).
PLATES_PER_LENS = {"smoke": 0, "quick": 60, "paper": 400}  # smoke: the row, not the cost
DEFAULT_PLATES = 60
# From this width every unread plate of an open bin is given, whatever the count above (not on smoke).
EVERY_PLATE_FROM_PX = {"smoke": None, "quick": 32, "paper": 32}


def wanted(cfg: RunConfig, reader: str) -> bool:
    """Whether the run asks for `reader` as a cascade (only by naming its chain: never in the full cross
    product, where it reads everything as any reader does)."""
    return cfg.chains is not None and cascade_name(reader) in cfg.chains


def width_bin(width_px: float) -> int:
    """Index of the WIDTH_BINS_PX bin holding `width_px` (the last bin is open-ended)."""
    return max(0, int(np.searchsorted(WIDTH_BINS_PX, width_px, side="right")) - 1)


def run_cascade(target: Target, ready: ReadyReader, cfg: RunConfig, rows: RowBuilder, out: Attacked,
                plates_per_lens: int | None = None) -> None:
    """Read with `ready` (a fitted reader whose cascade chain the run wants) the plate windows `choose`
    picks, and add its row and plate records to `out` (after the other chains: call it last)."""
    reader = ready.reader
    chain = cascade_name(reader.name)
    plates = target.plates
    settings = {"reader": ready.described}
    if ready.fit_error is not None:
        out.rows.append(rows.failed("reader", chain, ready.fit_error, reader=reader.name, settings=settings))
        return
    if plates is None:  # reading whole scenes: there is no plate window to hand it alone
        log.info("%s on %s: no plate windows to cascade over; not run", chain, target.lens_name)
        return
    limit = PLATES_PER_LENS.get(cfg.profile.name, DEFAULT_PLATES) if plates_per_lens is None else plates_per_lens
    every_from = EVERY_PLATE_FROM_PX.get(cfg.profile.name, 32) if plates_per_lens is None else None
    scored = [score_scene([], scene) for scene in plates.scenes]  # every scored plate, as not read
    records = [r for r in out.plates if r["lens"] == target.lens_name and r["seed"] == rows.seed]
    share, pick = choose(records, [s.name for s in plates.scenes], [max((o.width_px for o in w), default=-1)
                                                                     for w in scored], limit, every_from)
    t0 = time.perf_counter()
    outcomes_by_window: dict[int, list[PlateOutcome]] = {i: scored[i] for i in range(len(scored))}
    if pick:
        result = attempt(reader.name, "read", lambda: read_plates(
            reader, [plates.sensor[i] for i in pick], [plates.scenes[i] for i in pick], cfg.profile.batch_size,
            cfg.device, target.segment_sensor), cfg.budget_s, target.ctx.cache_dir)
        if isinstance(result, RowError):
            out.rows.append(rows.failed("reader", chain, result, reader=reader.name, settings=settings))
            return
        outcomes, _, _ = result
        given = iter(outcomes)
        for i in pick:  # read_plates scores each window's scored plates in order: one per window
            outcomes_by_window[i] = [next(given) for _ in scored[i]]
    seconds = time.perf_counter() - t0
    outcomes = [o for i in range(len(scored)) for o in outcomes_by_window[i]]
    read_now = sum(o.correct for i in pick for o in outcomes_by_window[i])
    open_bins = sorted(b for b, s in share.items() if s < OPEN_BIN_BELOW)
    every = "" if every_from is None else f"every one from {every_from} px, narrower ones while "
    note = (f"given the {len(pick)} widest plates ({every}at most {limit} in all) that no earlier chain read, in the width bins "
            f"{_bins_text(open_bins)} where the earlier chains read under {OPEN_BIN_BELOW:.0%}; it read {read_now} of "
            "them; every other plate counts as not read by it")
    row = plate_row(rows, "reader", chain, outcomes,
                    {"cascade_given": float(len(pick)), "cascade_read": float(read_now), "cascade_s": seconds,
                     "cascade_s_per_plate": seconds / len(pick) if pick else 0.0},
                    reader=reader.name, threat_model=reader.threat_model.value, settings=settings,
                    notes={**ready.notes, LEARNS: "true" if reader.learns else "false", "cascade": note})
    out.rows.append(row)
    out.plates.extend(plate_records(target, row, outcomes))
    log.info("%s on %s: %s (%.0f s)", chain, target.lens_name, note, seconds)


def choose(records: Sequence[dict], names: Sequence[str], widths: Sequence[int], limit: int,
           every_from_px: float | None = None) -> tuple[dict[int, float], list[int]]:
    """The share of plates read per width bin by the chains before the cascade (`records`: the run's
    per-plate records so far, each with ``scene``, ``correct`` and ``width_px``), and the windows the
    cascade reads: indices into `names` / `widths` (each window's scene name and its scored plate's
    width, -1 for none) of the windows no earlier chain read whose bin is open (read under
    OPEN_BIN_BELOW), widest first (ties: the earlier window): every one at least `every_from_px` wide (None:
    none by right), then narrower ones while fewer than `limit` are chosen."""
    read = {r["scene"] for r in records if r["correct"]}
    per_bin: dict[int, set] = {}
    for r in records:
        per_bin.setdefault(width_bin(r["width_px"]), set()).add(r["scene"])
    share = {b: float(np.mean([s in read for s in scenes])) for b, scenes in per_bin.items()}
    open_windows = [i for i, (name, w) in enumerate(zip(names, widths))
                    if w >= 0 and name not in read and share.get(width_bin(w), 0.0) < OPEN_BIN_BELOW]
    ordered = sorted(open_windows, key=lambda i: (-widths[i], i))
    owed = sum(1 for i in ordered if every_from_px is not None and widths[i] >= every_from_px)
    return share, ordered[:max(limit, owed, 0)]


def _bins_text(bins: Sequence[int]) -> str:
    edges = [*WIDTH_BINS_PX, None]
    parts = [f"{edges[b]}-{edges[b + 1]} px" if edges[b + 1] is not None else f"{edges[b]}+ px" for b in bins]
    return ", ".join(parts) if parts else "(none)"


def wanted_readers(cfg: RunConfig, ready: Sequence[ReadyReader]) -> list[ReadyReader]:
    """The fitted readers the run asks for as a cascade, in the order given."""
    return [r for r in ready if wanted(cfg, r.reader.name)]


