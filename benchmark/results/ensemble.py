"""The per-unit worst case over every attacker of a lens: the ensemble (in the spirit of AutoAttack).

Plates. A plate counts as read by the ensemble when ANY reader chain of the lens read it exactly
(rows of kind ``reader`` and ``chain`` with per-plate units, paired by plate name within a seed;
``reference`` rows such as ``raw>lpdr-oracle`` are measurements of the uncorrected image, not
attackers, and are left out as ``Entry.worst_case`` leaves them out). Its accuracy is pooled over
seeds as the leaderboard pools plates (hits over plates of every seed, with the Wilson 95 %
interval of that count; the per-seed accuracies give the seed spread, shown apart from it). Each
chain's contribution: the share of ensemble-read plates it read, and the share only it read.
Where the plate units carry each plate's width (a ``width_px`` value), the pooled accuracy (and
every paired comparison built on ``seed_plates``) counts the readable plates, those at least
``READABLE_MIN_WIDTH_PX`` wide, and the accuracy is also given per width bin over every scored plate
(``benchmark.results.plate_scoring.WIDTH_BINS_PX``, from 8 px); entries published before that carry
no widths, and their ensemble is over every plate they scored (>= LEGACY_READABLE_MIN_WIDTH_PX) only.

Scenes. A scene counts at its best restorer (rows of kind ``restorer`` with per-scene units,
paired by scene name within a seed): the ensemble PSNR is the mean over scenes of the per-scene
maximum over restorers, averaged over seeds, with a scene bootstrap interval (scenes resampled
within their seed).

Everything here is a pure function of rows (``benchmark.results.schema.Row``), so a run's rows and a
leaderboard entry's are treated alike; ``attacks`` limits the ensemble to some chains (the web
page's threat-model view).
"""

from __future__ import annotations

import dataclasses
import math
from collections.abc import Iterable, Sequence

import numpy as np

from benchmark.results import stats
from benchmark.results.plate_scoring import LEGACY_READABLE_MIN_WIDTH_PX, READABLE_MIN_WIDTH_PX, WIDTH_BINS_PX
from benchmark.results.schema import Row, Units

__all__ = ["Accuracy", "Contribution", "PlateEnsemble", "SceneEnsemble", "SeedPlates", "WidthBin", "WIDTH_VALUE",
           "chain_accuracy", "plate_ensemble", "pooled_min_width", "scene_ensemble", "seed_plates", "seed_scene_names",
           "seed_scenes",
           "strongest_chain"]

# Kinds of row whose outcomes join the ensemble (``reference`` rows are not attackers).
READER_KINDS = ("reader", "chain")
RESTORER_KINDS = ("restorer",)
# The per-plate value that carries a plate's width in pixels, where plate units record it.
WIDTH_VALUE = "width_px"


@dataclasses.dataclass(frozen=True)
class Accuracy:
    """Plates read over plates scored, pooled over seeds.

    Attributes:
        hits, n: Plates read and plates scored, summed over the seeds.
        interval: Wilson 95 % interval of hits / n (sampling error).
        seed_values: hits / n of each seed (None where the seed scored no plate), for the seed spread.
    """

    hits: int
    n: int
    interval: tuple[float, float]
    seed_values: tuple[float | None, ...]

    @property
    def value(self) -> float:
        return self.hits / self.n if self.n else math.nan

    @property
    def seed_std(self) -> float:
        """Standard deviation (ddof 1) of the per-seed accuracies; 0 for one seed."""
        values = [v for v in self.seed_values if v is not None]
        return float(np.std(values, ddof=1)) if len(values) > 1 else 0.0

    @classmethod
    def of(cls, per_seed: Sequence[tuple[int, int]]) -> Accuracy:
        """From (hits, n) per seed."""
        hits, n = sum(h for h, _ in per_seed), sum(k for _, k in per_seed)
        return cls(hits, n, stats.wilson_interval(hits, n), tuple(h / k if k else None for h, k in per_seed))

    def text(self, digits: int = 1) -> str:
        """"acc ± seed sd [low, high]" in percent (the sd left out for one seed)."""
        spread = f" ± {100 * self.seed_std:.{digits}f}" if self.seed_std else ""
        low, high = self.interval
        return f"{100 * self.value:.{digits}f}{spread} [{100 * low:.{digits}f}, {100 * high:.{digits}f}]"


@dataclasses.dataclass(frozen=True)
class SeedPlates:
    """The plates of one seed and which chain read each.

    Attributes:
        seed: The seed.
        names: Plate names (``Units.names()``) that every chain of the seed scored, in one order.
        chains: The reader chains of the seed (attack names).
        read: (len(chains), len(names)) bool: chain c read plate i exactly.
        widths: (len(names),) plate widths in px, or None when the units do not record them.
    """

    seed: int
    names: tuple[str, ...]
    chains: tuple[str, ...]
    read: np.ndarray
    widths: np.ndarray | None

    @property
    def ensemble(self) -> np.ndarray:
        """(len(names),) bool: read by at least one chain."""
        return self.read.any(axis=0) if self.chains else np.zeros(len(self.names), dtype=bool)

    def readable(self) -> SeedPlates:
        """The plates at least READABLE_MIN_WIDTH_PX wide (all of them where widths are not recorded)."""
        if self.widths is None:
            return self
        keep = np.flatnonzero(self.widths >= READABLE_MIN_WIDTH_PX)
        return dataclasses.replace(self, names=tuple(self.names[i] for i in keep), read=self.read[:, keep],
                                   widths=self.widths[keep])

    def of_chains(self, chains: Iterable[str]) -> SeedPlates:
        """The same plates with only the given chains (those of them this seed has)."""
        keep = [i for i, c in enumerate(self.chains) if c in set(chains)]
        return dataclasses.replace(self, chains=tuple(self.chains[i] for i in keep), read=self.read[keep])


@dataclasses.dataclass(frozen=True)
class Contribution:
    """One chain's part in the ensemble, pooled over seeds.

    Attributes:
        attack: The chain.
        seeds: The seeds it ran on.
        read: Ensemble-read plates it read (every plate it read is one).
        only: Ensemble-read plates no other chain read.
        of: Ensemble-read plates over all seeds (the denominator of both shares).
    """

    attack: str
    seeds: tuple[int, ...]
    read: int
    only: int
    of: int

    @property
    def share(self) -> float:
        return self.read / self.of if self.of else 0.0

    @property
    def only_share(self) -> float:
        return self.only / self.of if self.of else 0.0


@dataclasses.dataclass(frozen=True)
class WidthBin:
    """The ensemble's accuracy on plates of width in [low_px, high_px) (high_px may be inf)."""

    low_px: float
    high_px: float
    accuracy: Accuracy


@dataclasses.dataclass(frozen=True)
class PlateEnsemble:
    """The per-plate worst case over the reader chains of one lens (see the module docstring).

    Attributes:
        chains: Every chain that joined it (on at least one seed), in the order the rows name them.
        per_seed: The readable plates of each seed (``SeedPlates.readable``).
        accuracy: The ensemble's accuracy over the readable plates.
        bins: Per width bin over every scored plate (bins without plates left out), or None when the
            units record no widths.
        contributions: One per chain, in `chains` order.
    """

    chains: tuple[str, ...]
    per_seed: tuple[SeedPlates, ...]
    accuracy: Accuracy
    bins: tuple[WidthBin, ...] | None
    contributions: tuple[Contribution, ...]

    @property
    def seeds(self) -> tuple[int, ...]:
        return tuple(p.seed for p in self.per_seed)

    def min_width_px(self) -> float:
        """The smallest plate width the pooled accuracy covers: LEGACY_READABLE_MIN_WIDTH_PX where the
        units record no widths or scored no plate below it (runs before plates were scored from 8 px),
        else READABLE_MIN_WIDTH_PX."""
        return float(_pooled_from(None if self.bins is None else min(b.low_px for b in self.bins)))


@dataclasses.dataclass(frozen=True)
class SceneEnsemble:
    """Each scene at its best restorer, for one metric (PSNR by default) of one lens.

    Attributes:
        metric: The per-scene value (``psnr_db``).
        restorers: Every restorer that joined it.
        mean: Mean over seeds of each seed's mean over scenes of the per-scene best.
        seed_values: That mean per seed.
        interval: Scene-bootstrap 95 % interval of `mean` (scenes resampled within their seed).
        n_scenes: Scenes over all seeds.
        best_counts: Per restorer (in `restorers` order), the scenes where it was the best.
    """

    metric: str
    restorers: tuple[str, ...]
    mean: float
    seed_values: tuple[float, ...]
    interval: tuple[float, float]
    n_scenes: int
    best_counts: tuple[int, ...]

    @property
    def seed_std(self) -> float:
        return float(np.std(self.seed_values, ddof=1)) if len(self.seed_values) > 1 else 0.0

    def text(self, digits: int = 2) -> str:
        spread = f" ± {self.seed_std:.{digits}f}" if self.seed_std else ""
        return f"{self.mean:.{digits}f}{spread} [{self.interval[0]:.{digits}f}, {self.interval[1]:.{digits}f}]"


def pooled_min_width(rows: Iterable[Row]) -> int:
    """The smallest plate width the pooled plate figures of `rows` (plate_acc, n_plates) count:
    READABLE_MIN_WIDTH_PX where a reader row's units record a plate narrower than
    LEGACY_READABLE_MIN_WIDTH_PX, else the legacy width (rows of runs that scored plates from 32 px)."""
    widths = [w for row in rows if row.kind in READER_KINDS and (u := row.units) is not None and u.unit == "plate"
              for w in u.values.get(WIDTH_VALUE, ())]
    return _pooled_from(min(widths, default=None))


def _pooled_from(narrowest_px: float | None) -> int:
    """Where pooled plate figures start, given the narrowest scored plate (None: widths not recorded):
    plates narrower than the legacy start mean plates were scored from 8 px."""
    if narrowest_px is None or narrowest_px >= LEGACY_READABLE_MIN_WIDTH_PX:
        return LEGACY_READABLE_MIN_WIDTH_PX
    return READABLE_MIN_WIDTH_PX


def _units_rows(rows: Iterable[Row], kinds: Sequence[str], unit: str, value: str,
                attacks: set[str] | None) -> dict[int, list[Row]]:
    """seed -> the ok rows of `kinds` (in `attacks` when given) whose units are of `unit` and hold `value`."""
    out: dict[int, list[Row]] = {}
    for row in rows:
        u = row.units
        if (row.ok and row.kind in kinds and (attacks is None or row.attack in attacks) and u is not None
                and u.unit == unit and value in u.values):
            out.setdefault(row.seed, []).append(row)
    return out


def _aligned(rows: Sequence[Row]) -> tuple[list[str], list[list[int]]]:
    """The unit names every row holds (in the first row's order) and each row's positions of them."""
    units: list[Units] = [r.units for r in rows]  # type: ignore[misc]
    names = [u.names() for u in units]
    common = set(names[0]).intersection(*names[1:])
    order = [n for n in names[0] if n in common]
    positions = [{k: i for i, k in enumerate(n)} for n in names]  # one index per row (was one per plate: O(n^2))
    return order, [[where[name] for name in order] for where in positions]


def seed_plates(rows: Iterable[Row], seed: int, attacks: set[str] | None = None,
                readable_only: bool = True) -> SeedPlates | None:
    """The plates of `seed` that every reader chain with per-plate units scored, and which chain read
    each (None when no chain of that seed carries per-plate units): the readable ones
    (``SeedPlates.readable``), or every scored one with `readable_only` False. Rows disagreeing on a
    plate's width are an error naming both."""
    found = _units_rows(rows, READER_KINDS, "plate", "correct", attacks).get(seed)
    if not found:
        return None
    names, index = _aligned(found)
    read = np.array([[r.units.values["correct"][i] == 1 for i in idx]  # type: ignore[union-attr]
                     for r, idx in zip(found, index)], dtype=bool).reshape(len(found), len(names))
    widths = None
    if all(WIDTH_VALUE in r.units.values for r in found):  # type: ignore[union-attr]
        columns = [np.array(r.units.values[WIDTH_VALUE], dtype=float)[idx]  # type: ignore[union-attr]
                   for r, idx in zip(found, index)]
        for r, column in zip(found[1:], columns[1:]):
            if not np.array_equal(column, columns[0]):
                raise ValueError(f"seed {seed}: rows {found[0].lens}/{found[0].attack} and {r.lens}/{r.attack} "
                                 f"give the same plates different {WIDTH_VALUE}")
        widths = columns[0]
    plates = SeedPlates(seed, tuple(names), tuple(r.attack for r in found), read, widths)
    return plates.readable() if readable_only else plates


def _bins(per_seed: Sequence[SeedPlates], bins_px: Sequence[float]) -> tuple[WidthBin, ...]:
    edges = list(bins_px) + [math.inf]
    out = []
    for low, high in zip(edges[:-1], edges[1:]):
        counts = []
        for p in per_seed:
            inside = (p.widths >= low) & (p.widths < high)  # type: ignore[operator]
            counts.append((int(np.sum(p.ensemble & inside)), int(np.sum(inside))))
        if sum(n for _, n in counts):
            out.append(WidthBin(float(low), float(high), Accuracy.of(counts)))
    return tuple(out)


def plate_ensemble(rows: Iterable[Row], attacks: set[str] | None = None,
                   bins_px: Sequence[float] = WIDTH_BINS_PX) -> PlateEnsemble | None:
    """The per-plate worst case over the reader chains of `rows` (one lens's; `attacks` limits the
    chains), or None when no chain carries per-plate units. Seeds are taken in increasing order."""
    rows = list(rows)
    seeds = sorted(_units_rows(rows, READER_KINDS, "plate", "correct", attacks))
    scored = [p for s in seeds if (p := seed_plates(rows, s, attacks, readable_only=False)) is not None]
    if not scored:
        return None
    per_seed = [p.readable() for p in scored]
    chains = tuple(dict.fromkeys(c for p in per_seed for c in p.chains))
    accuracy = Accuracy.of([(int(p.ensemble.sum()), len(p.names)) for p in per_seed])
    bins = _bins(scored, bins_px) if all(p.widths is not None for p in scored) else None
    contributions = []
    for chain in chains:
        read = only = 0
        ran = []
        for p in per_seed:
            if chain not in p.chains:
                continue
            ran.append(p.seed)
            i = p.chains.index(chain)
            mine = p.read[i]
            others = np.delete(p.read, i, axis=0).any(axis=0) if len(p.chains) > 1 else np.zeros_like(mine)
            read += int(mine.sum())
            only += int((mine & ~others).sum())
        contributions.append(Contribution(chain, tuple(ran), read, only, accuracy.hits))
    return PlateEnsemble(chains, tuple(per_seed), accuracy, bins, tuple(contributions))


def chain_accuracy(ensemble: PlateEnsemble, attack: str) -> Accuracy | None:
    """One chain's own accuracy on the ensemble's plates of the seeds it ran on (None: not in it)."""
    counts = [(int(p.read[p.chains.index(attack)].sum()), len(p.names)) for p in ensemble.per_seed
              if attack in p.chains]
    return Accuracy.of(counts) if counts else None


def strongest_chain(ensemble: PlateEnsemble) -> tuple[str, Accuracy] | None:
    """The single chain that read the most plates on the seeds every chain ran (pooled; with no such
    seed, over its own seeds), ties to the chain named first; with its own accuracy."""
    if not ensemble.chains:
        return None
    shared = [p for p in ensemble.per_seed if set(ensemble.chains) <= set(p.chains)]

    def rank(chain: str) -> float:
        plates = shared or [p for p in ensemble.per_seed if chain in p.chains]
        n = sum(len(p.names) for p in plates)
        return sum(int(p.read[p.chains.index(chain)].sum()) for p in plates) / n if n else 0.0

    best = max(ensemble.chains, key=rank)
    accuracy = chain_accuracy(ensemble, best)
    assert accuracy is not None
    return best, accuracy


def seed_scenes(rows: Iterable[Row], seed: int, metric: str = "psnr_db", attacks: set[str] | None = None
                ) -> tuple[tuple[str, ...], np.ndarray] | None:
    """(restorers, (n_scenes, R) per-scene values) of `seed` on the scenes every restorer scored."""
    found = _units_rows(rows, RESTORER_KINDS, "scene", metric, attacks).get(seed)
    if not found:
        return None
    names, index = _aligned(found)
    if not names:
        return None
    values = np.stack([np.asarray(r.units.values[metric], dtype=float)[idx]  # type: ignore[union-attr]
                       for r, idx in zip(found, index)], axis=1)
    return tuple(r.attack for r in found), values


def seed_scene_names(rows: Iterable[Row], seed: int, metric: str = "psnr_db") -> list[str]:
    """The scene names ``seed_scenes`` orders its values by (empty where no restorer of `seed` has units)."""
    found = _units_rows(rows, RESTORER_KINDS, "scene", metric, None).get(seed)
    return _aligned(found)[0] if found else []


def scene_ensemble(rows: Iterable[Row], metric: str = "psnr_db", attacks: set[str] | None = None,
                   n_resamples: int = 4000) -> SceneEnsemble | None:
    """Each scene at its best restorer (see the module docstring), or None when no restorer of `rows`
    carries per-scene `metric` units."""
    rows = list(rows)
    seeds = sorted(_units_rows(rows, RESTORER_KINDS, "scene", metric, attacks))
    per_seed = [(s, found) for s in seeds if (found := seed_scenes(rows, s, metric, attacks)) is not None]
    if not per_seed:
        return None
    restorers = tuple(dict.fromkeys(r for _, (names, _) in per_seed for r in names))
    best = [values.max(axis=1) for _, (_, values) in per_seed]
    counts = dict.fromkeys(restorers, 0)
    for _, (names, values) in per_seed:
        for i in np.argmax(values, axis=1):  # the first of equal maxima
            counts[names[int(i)]] += 1
    seed_values = tuple(float(b.mean()) for b in best)
    interval = stats.stratified_bootstrap_mean_interval(best, n_resamples=n_resamples)
    return SceneEnsemble(metric, restorers, float(np.mean(seed_values)), seed_values, interval,
                         int(sum(b.size for b in best)), tuple(counts[r] for r in restorers))
