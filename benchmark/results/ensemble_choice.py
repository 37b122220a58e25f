"""Choosing the standard attack ensemble from measurements: which chains decide.

On a set of leaderboard entries (the published quick ones), for every attack chain of every lens:

- plates it decides: plates of the lens's plate ensemble (benchmark.results.ensemble) it read
  **first** (the first chain, in the entry's chain order, i.e. the order its run evaluated them, that
  read the plate) and plates it read **only** (no other chain of that seed read them);
- scenes it decides: scenes where it is the best restorer (the first of equal maxima, as
  ``scene_ensemble`` counts them);
- its **removal effect**: how much the lens's ensemble plate accuracy (points, pooled over seeds)
  and ensemble PSNR (dB, mean over seeds of the mean over scenes of the per-scene best) drop when the
  ensemble is recomputed without it (``plate_ensemble`` / ``seed_scenes`` with the other chains).

The rule (``keeps``): a chain stays in the standard ensemble when its removal changes some lens's
ensemble plate accuracy by more than ``PLATE_POINTS`` points or its ensemble PSNR by more than
``PSNR_DB`` dB. To those it adds ``lpdr`` (the paper's detector pipeline) on the sensor image and after
the strongest restorer (the one that is the best restorer on the most scenes of the entries), and the
learned reader, which the rule keeps once entries hold it. Chains that each decide nothing alone can still
read plates together (two readers after two restorers that read the same hard plates): on runs with per-unit
outcomes, ``complete_ensemble`` then adds, one at a time, the chain that brings the ensemble closest to what
every chain reads, until dropping all the others moves no lens past the thresholds. ``PROPOSED_ENSEMBLE`` is what that selects on the published quick
entries (docs/ensemble.md, written by ``python -m benchmark.studies.ensemble_choice_study``;
tests/benchmark/results/test_ensemble_choice.py recomputes it, so it cannot drift from the entries).

``STANDARD_ENSEMBLE`` is the run's default (``benchmark.runner.runner.standard_attackers``): the proposal (with
the learned reader on the sensor image) and the ``raw`` reference (the uncorrected image's PSNR, no chain).
"""

from __future__ import annotations

import dataclasses
import math
from collections.abc import Iterable, Sequence

import numpy as np

from benchmark.results.ensemble import RESTORER_KINDS, SeedPlates, plate_ensemble, seed_plates, seed_scenes
from benchmark.results.entries import Entry
from benchmark.results.schema import chain_parts

__all__ = ["ChainEffect", "Outcomes", "PLATE_POINTS", "PSNR_DB", "DOCS", "complete_ensemble", "keeps", "with_restorers",
           "proposed_ensemble", "removal_effects", "strongest_restorer", "ensemble_values"]

# The rule's thresholds: a chain whose removal moves some lens's ensemble by more than this stays.
PLATE_POINTS = 1.0
PSNR_DB = 0.1
# The paper's detector pipeline: kept on the sensor image and after the strongest restorer.
PAPER_READER = "lpdr"
DOCS = "docs/ensemble.md"

@dataclasses.dataclass(frozen=True)
class ChainEffect:
    """One chain of one entry: what it decides and what removing it costs the ensemble.

    Attributes:
        lens, profile, scenes: The entry.
        attack: The chain (a reader, ``restorer>reader`` chain or restorer).
        kind: "plates" (a reader chain: joins the plate ensemble) or "scenes" (a restorer).
        first: Plates it read first (plates chains), pooled over seeds; 0 for a restorer.
        only: Plates only it read; 0 for a restorer.
        best_scenes: Scenes where it is the best restorer; 0 for a reader chain.
        plate_points: Ensemble plate accuracy with it minus without it, in points (0 for a restorer).
        psnr_db: Ensemble PSNR with it minus without it, in dB (0 for a reader chain).
    """

    lens: str
    profile: str
    scenes: str
    attack: str
    kind: str
    first: int
    only: int
    best_scenes: int
    plate_points: float
    psnr_db: float

    @property
    def decides(self) -> bool:
        """It decides some plate (first or only reader) or scene (its best restorer)."""
        return bool(self.first or self.only or self.best_scenes)

    @property
    def matters(self) -> bool:
        """Its removal moves the ensemble past the rule's thresholds."""
        return abs(self.plate_points) > PLATE_POINTS or abs(self.psnr_db) > PSNR_DB


def _scene_mean(rows: Sequence, attacks: set[str] | None, metric: str = "psnr_db") -> float | None:
    """The ensemble's scene figure (as ``scene_ensemble``'s ``mean``, without its bootstrap): mean over
    seeds of each seed's mean over scenes of the per-scene best restorer; None with no restorer."""
    seeds = sorted({r.seed for r in rows if r.kind in RESTORER_KINDS})
    means = []
    for seed in seeds:
        found = seed_scenes(rows, seed, metric, attacks)
        if found is not None:
            means.append(float(found[1].max(axis=1).mean()))
    return float(np.mean(means)) if means else None


def _plate_accuracy(rows: Sequence, attacks: set[str] | None) -> float:
    """The ensemble's pooled plate accuracy over `attacks` (0 when no chain is left to read)."""
    ensemble = plate_ensemble(rows, attacks)
    return 0.0 if ensemble is None else ensemble.accuracy.value


def ensemble_values(entry: Entry, attacks: set[str] | None = None) -> tuple[float | None, float | None]:
    """(ensemble plate accuracy in points, ensemble PSNR in dB) of `entry` over `attacks` (None: every
    chain); a figure is None where the entry has no per-unit outcomes for it."""
    has_plates = plate_ensemble(entry.rows) is not None
    plates = 100 * _plate_accuracy(entry.rows, attacks) if has_plates else None
    return plates, _scene_mean(entry.rows, attacks)


def _entry_effects(entry: Entry) -> list[ChainEffect]:
    rows = entry.rows
    out = []
    ensemble = plate_ensemble(rows)
    if ensemble is not None:
        full = 100 * ensemble.accuracy.value
        chains = set(ensemble.chains)
        for chain in ensemble.chains:
            first = only = 0
            for p in ensemble.per_seed:
                if chain not in p.chains:
                    continue
                i = p.chains.index(chain)
                read_by = p.read.argmax(axis=0)  # the first chain (in the seed's order) that read each plate
                first += int((p.read[i] & (read_by == i)).sum())
                only += int((p.read[i] & (p.read.sum(axis=0) == 1)).sum())
            without = 100 * _plate_accuracy(rows, chains - {chain})
            out.append(ChainEffect(entry.lens, entry.profile, entry.scenes, chain, "plates", first, only, 0,
                                   full - without, 0.0))
    restorers = list(dict.fromkeys(r.attack for r in rows if r.ok and r.kind in RESTORER_KINDS
                                   and r.units is not None and r.units.unit == "scene"))
    full_psnr = _scene_mean(rows, None)
    if full_psnr is not None:
        best = dict.fromkeys(restorers, 0)
        for seed in sorted({r.seed for r in rows}):
            found = seed_scenes(rows, seed)
            if found is not None:
                names, values = found
                for i in np.argmax(values, axis=1):
                    best[names[int(i)]] += 1
        for restorer in restorers:
            left = _scene_mean(rows, set(restorers) - {restorer})
            delta = math.inf if left is None else full_psnr - left
            out.append(ChainEffect(entry.lens, entry.profile, entry.scenes, restorer, "scenes", 0, 0,
                                   best[restorer], 0.0, delta))
    return out


def removal_effects(entries: Iterable[Entry]) -> list[ChainEffect]:
    """Every chain of every entry with what it decides and its removal effect (see the module
    docstring), entries in the given order, chains in each entry's order (reader chains, then restorers)."""
    return [effect for entry in entries for effect in _entry_effects(entry)]


def keeps(effects: Iterable[ChainEffect]) -> list[str]:
    """The chains the rule keeps: those whose removal moves some entry's ensemble past a threshold
    (in order of first appearance)."""
    return list(dict.fromkeys(e.attack for e in effects if e.matters))


def strongest_restorer(effects: Iterable[ChainEffect]) -> str | None:
    """The restorer that is the best restorer on the most scenes over every entry (ties: first named)."""
    counts: dict[str, int] = {}
    for e in effects:
        if e.kind == "scenes":
            counts[e.attack] = counts.get(e.attack, 0) + e.best_scenes
    return max(counts, key=lambda k: counts[k]) if counts else None


def proposed_ensemble(effects: Sequence[ChainEffect]) -> tuple[str, ...]:
    """The rule's chains plus ``lpdr`` on the sensor image and after the strongest restorer, sorted."""
    strongest = strongest_restorer(effects)
    extra = [PAPER_READER] + ([f"{strongest}>{PAPER_READER}"] if strongest else [])
    return tuple(sorted(set(keeps(effects)) | set(extra)))


@dataclasses.dataclass(frozen=True)
class Outcomes:
    """One lens-seed's per-unit outcomes as ``complete_ensemble`` weighs them.

    Attributes:
        lens: The lens.
        plates: Which reader chain read which readable plate (None without per-plate units).
        restorers: The restorers with per-scene PSNR, in the run's order.
        psnr: (n_scenes, len(restorers)) PSNR in dB (None without per-scene units).
        pass_s: Per chain, the seconds its row measured for its pass over its images (``n_images`` /
            ``images_per_s``; a reader chain's row holds its reader's pass; the cascade's ``cascade_s``).
        fit_s: Per attacker, the seconds its fit took (``fit_s`` of a restorer's row; of a reader's row on the
            sensor image, or of the first chain read with a reader that has none); a chain pays it once for each
            attacker it is the first to use.
    """

    lens: str
    plates: SeedPlates | None
    restorers: tuple[str, ...]
    psnr: np.ndarray | None
    pass_s: dict[str, float] = dataclasses.field(default_factory=dict)
    fit_s: dict[str, float] = dataclasses.field(default_factory=dict)

    @classmethod
    def of(cls, rows: Sequence, lens: str, seed: int) -> Outcomes:
        """The outcomes of `lens` at `seed` in `rows` (every chain of the run)."""
        mine = [r for r in rows if r.lens == lens and r.seed == seed]
        scenes = seed_scenes(mine, seed)
        pass_s, fit_s = {}, {}
        for r in mine:
            m = r.metrics
            pass_s[r.attack] = float(m.get("cascade_s", 0.0)) + (
                float(m["n_images"]) / float(m["images_per_s"]) if m.get("images_per_s") and "n_images" in m else 0.0)
            if "fit_s" in m:  # a chain row's is its reader's fit
                fit_s[r.reader if r.restorer and r.reader else r.attack] = float(m["fit_s"])
        return cls(lens, seed_plates(mine, seed), scenes[0] if scenes else (),
                   None if scenes is None else scenes[1], pass_s, fit_s)

    @property
    def chains(self) -> tuple[str, ...]:
        """Every reader chain and restorer, in the run's order."""
        return (self.plates.chains if self.plates is not None else ()) + self.restorers

    def loss(self, kept: set[str]) -> tuple[float, float]:
        """(plate accuracy in points, ensemble PSNR in dB) that every chain reaches and `kept` alone does not."""
        points = db = 0.0
        if self.plates is not None and self.plates.names:
            mask = np.array([c in kept for c in self.plates.chains])
            read = self.plates.read[mask].any(axis=0) if mask.any() else np.zeros(len(self.plates.names), bool)
            points = 100.0 * (self.plates.ensemble.mean() - read.mean())
        if self.psnr is not None:
            mask = np.array([r in kept for r in self.restorers])
            best = self.psnr.max(axis=1).mean()
            db = float(best - (self.psnr[:, mask].max(axis=1).mean() if mask.any() else 0.0))
        return float(points), db


def _with_parts(chain: str, restorers: set[str]) -> set[str]:
    """A chain and the restorer whose output it reads (a reader chain after a restorer needs that restorer)."""
    head = chain.split(">")[0]
    return {chain, head} if ">" in chain and head in restorers else {chain}


def _cost(outcomes: Outcomes, new: set[str], kept: set[str]) -> float:
    """Seconds that running the chains `new` beside `kept` adds on one lens-seed: their passes, and the fits of
    the attackers no kept chain runs yet."""
    used = set().union(*(chain_parts(c) for c in kept)) if kept else set()
    fresh = set().union(*(chain_parts(c) for c in new)) - used
    return sum(outcomes.pass_s.get(c, 0.0) for c in new) + sum(outcomes.fit_s.get(a, 0.0) for a in fresh)


def with_restorers(chains: Iterable[str], outcomes: Sequence[Outcomes]) -> set[str]:
    """`chains` and the restorers (of `outcomes`) whose output their reader chains read."""
    restorers = {r for o in outcomes for r in o.restorers}
    return set().union(*(_with_parts(c, restorers) for c in chains))


def complete_ensemble(start: Iterable[str], outcomes: Sequence[Outcomes]) -> tuple[tuple[str, ...], tuple[str, ...]]:
    """(chains, the ones added in turn): `start` with the restorers its reader chains read, and then, one at a time,
    the chain (with its restorer) that most reduces the excess over the rule's thresholds of what dropping every
    other chain costs (summed over `outcomes` in units of the thresholds) per second of what it adds (``_cost``,
    summed over `outcomes`, at least 1 s); ties go to the run's order. It stops when no lens-seed's loss
    exceeds ``PLATE_POINTS`` or ``PSNR_DB``. Each step strictly reduces the excess (a chain that reads a plate
    the kept ones miss recovers it), so it ends."""
    restorers = {r for o in outcomes for r in o.restorers}
    kept = with_restorers(start, outcomes)

    def excess(chains: set[str]) -> float:
        total = 0.0
        for o in outcomes:
            points, db = o.loss(chains)
            # (a loss exactly at a threshold is within it; 1e-9 absorbs the rounding of the means)
            total += max(0.0, points / PLATE_POINTS - 1.0 - 1e-9) + max(0.0, db / PSNR_DB - 1.0 - 1e-9)
        return total

    order = list(dict.fromkeys(c for o in outcomes for c in o.chains))
    added: list[str] = []
    current = excess(kept)
    while current > 0.0:
        scored = []
        for rank, chain in enumerate(order):
            if chain in kept:
                continue
            new = _with_parts(chain, restorers) - kept
            after = excess(kept | new)
            if after < current:
                cost = max(1.0, sum(_cost(o, new, kept) for o in outcomes))
                scored.append((-(current - after) / cost, rank, chain, after))
        if not scored:
            break
        _, _, chain, current = min(scored)
        kept |= _with_parts(chain, restorers)
        added.append(chain)
    return tuple(sorted(kept)), tuple(added)
