"""The leaderboard's one interval convention: a figure over seeds with its pooled 95 % interval, the seed
spread kept apart.

A figure is pooled over the units (scenes, plates) of every seed its rows ran: plate accuracy is
plates read over plates scored, summed over seeds, with the Wilson 95 % interval of that count
(``benchmark.results.ensemble``); a per-scene mean (PSNR, SSIM) is the mean over seeds of each seed's
mean over scenes, with a scene bootstrap (scenes resampled within their seed,
``stats.stratified_bootstrap_mean_interval``); mIoU is the mean over seeds of each seed's mIoU pooled
over its scenes (intersections and unions summed per class), with the same scene bootstrap. The seed
spread (standard deviation of the per-seed figures) is a separate number: it measures how much a
re-trained lens or attacker moves, not the sampling error of the scenes and plates.

Where an entry's rows carry no per-unit outcomes for the figure (``Row.units``; entries published
before they were kept, or metrics whose units are not kept, such as mA and OA), there is no pooled
interval: ``Pooled.interval`` is None and ``Pooled.missing`` names what is missing, never an interval
made up from the per-seed ones.
"""

from __future__ import annotations

import dataclasses

import numpy as np

from benchmark.results.ensemble import Accuracy, plate_ensemble, scene_ensemble
from benchmark.results.entries import Entry, Stat

__all__ = ["N_RESAMPLES", "Pooled", "chain_metric", "chain_plates", "miou", "plates", "utility"]

N_RESAMPLES = 4000
# What the utility rows' per-scene units (intersection and union per class) cannot give.
_NOT_KEPT = {"mean_acc": "per-scene class accuracies", "overall_acc": "per-scene pixel accuracies"}


@dataclasses.dataclass(frozen=True)
class Pooled:
    """One figure of one entry (or chain) over its seeds.

    Attributes:
        value: The figure (pooled where `interval` is given, else the mean over seeds).
        interval: Its pooled 95 % interval, or None without per-unit outcomes.
        seed_std: Standard deviation (ddof 1) of the per-seed figures; 0 for one seed.
        n_seeds: Seeds that have the figure.
        missing: Why there is no interval ("per-scene outcomes", ...), "" where there is one.
    """

    value: float
    interval: tuple[float, float] | None
    seed_std: float
    n_seeds: int
    missing: str = ""

    def text(self, digits: int, scale: float = 1.0) -> str:
        """"value [low, high]" (scaled), or "value (no <missing>)" without an interval."""
        if self.interval is None:
            return f"{self.value * scale:.{digits}f} (no {self.missing})"
        low, high = self.interval
        return f"{self.value * scale:.{digits}f} [{low * scale:.{digits}f}, {high * scale:.{digits}f}]"

    def spread_text(self, digits: int, scale: float = 1.0) -> str:
        """The seed spread; "" for one seed (no spread to show)."""
        return f"{self.seed_std * scale:.{digits}f}" if self.n_seeds > 1 else ""


def _unpooled(stat: Stat, missing: str) -> Pooled:
    return Pooled(stat.mean, None, stat.std, sum(v is not None for v in stat.values), missing)


def _miou(sums: list[np.ndarray]) -> np.ndarray:
    """Mean over strata of each stratum's pooled mIoU; a stratum's summed intersections and unions
    (R, 2, C) -> (R,) (R resamples)."""
    values = []
    for x in sums:
        inter, union = x[:, 0], x[:, 1]  # (R, C)
        present = union > 0
        ratio = np.where(present, inter / np.where(present, union, 1.0), 0.0)
        values.append(ratio.sum(axis=1) / np.maximum(present.sum(axis=1), 1))
    return np.mean(values, axis=0)


def _resampled_sums(x: np.ndarray, draws: np.ndarray) -> np.ndarray:
    """The sums over each resample's scenes, x (n, 2, C) and draws (R, n) of scene indices -> (R, 2, C):
    a count matrix times x, never the (R, n, 2, C) gather. Exact: intersections and unions are pixel
    counts, whose float64 sums are exact in any order."""
    r, n = draws.shape
    counts = np.bincount((draws + n * np.arange(r)[:, None]).ravel(), minlength=r * n).reshape(r, n)
    return np.einsum("rn,nkc->rkc", counts.astype(float), x)


def miou(entry: Entry, n_resamples: int = N_RESAMPLES, seed: int = 0) -> Pooled | None:
    """The entry's mIoU with a scene bootstrap (within seeds) of its per-scene intersections and unions;
    None without a utility figure. Deterministic (fixed resampling seed)."""
    stat = entry.metric("utility", "miou")
    chain = entry.chain("utility")
    if stat is None or chain is None:
        return None
    strata = []
    for row in chain.rows:
        u = row.units
        if row.metric("miou") is None:
            continue
        if u is None or u.unit != "scene" or not {"intersection", "union"} <= set(u.values):
            return _unpooled(stat, "per-scene outcomes")
        strata.append(np.stack([np.asarray(u.values["intersection"], dtype=float),
                                np.asarray(u.values["union"], dtype=float)], axis=1))  # (n, 2, C)
    if not strata:
        return _unpooled(stat, "per-scene outcomes")
    rng = np.random.default_rng(seed)
    draws = [rng.integers(0, x.shape[0], size=(n_resamples, x.shape[0])) for x in strata]
    resampled = _miou([_resampled_sums(x, d) for x, d in zip(strata, draws)])
    point = float(_miou([x.sum(axis=0)[None] for x in strata])[0])
    low, high = np.quantile(resampled, [0.025, 0.975])
    return Pooled(point, (float(low), float(high)), stat.std, len(strata))


def _accuracy(accuracy: Accuracy) -> Pooled:
    return Pooled(accuracy.value, accuracy.interval, accuracy.seed_std,
                  sum(v is not None for v in accuracy.seed_values))


def plates(entry: Entry, attacks: set[str] | None = None) -> Pooled | None:
    """Plates read by any of `attacks` (None: every reader chain; one chain: that chain's own accuracy),
    pooled over seeds with Wilson 95 %; None where no such chain has plate accuracy, and no interval
    where none carries per-plate outcomes."""
    ensemble = plate_ensemble(entry.rows, attacks)
    if ensemble is not None:
        return _accuracy(ensemble.accuracy)
    if attacks is not None and len(attacks) == 1:
        stat = entry.metric(next(iter(attacks)), "plate_acc")
        return None if stat is None else _unpooled(stat, "per-plate outcomes")
    return None


def chain_plates(entry: Entry, attack: str) -> Pooled | None:
    """One reader chain's own plate accuracy (reference rows too), its plates pooled over its seeds with
    Wilson 95 %; None where it has no plate accuracy, no interval where a seed's row has no per-plate outcomes."""
    chain = entry.chain(attack)
    stat = None if chain is None else chain.metrics.get("plate_acc")
    if chain is None or stat is None:
        return None
    counts = []
    for row in chain.rows:
        if row.metric("plate_acc") is None:
            continue
        u = row.units
        if u is None or u.unit != "plate" or "correct" not in u.values:
            return _unpooled(stat, "per-plate outcomes")
        correct = [c for c in u.values["correct"] if c is not None]
        counts.append((int(sum(c == 1 for c in correct)), len(correct)))
    return _accuracy(Accuracy.of(counts)) if counts else _unpooled(stat, "per-plate outcomes")


def chain_metric(entry: Entry, attack: str, metric: str) -> Pooled | None:
    """A restorer's per-scene figure (``psnr_db``, ``ssim``) pooled over its scenes and seeds (scene
    bootstrap within seeds); None where the chain has no such figure, no interval where a seed's row
    carries no per-scene values of it."""
    chain = entry.chain(attack)
    stat = None if chain is None else chain.metrics.get(metric)
    if chain is None or stat is None:
        return None
    rows = [r for r in chain.rows if r.metric(metric) is not None]
    if any(r.units is None or r.units.unit != "scene" or metric not in r.units.values for r in rows):
        return _unpooled(stat, "per-scene outcomes")
    found = scene_ensemble(rows, metric, {attack}, n_resamples=N_RESAMPLES)
    if found is None:
        return _unpooled(stat, "per-scene outcomes")
    return Pooled(found.mean, found.interval, found.seed_std, len(found.seed_values))


def utility(entry: Entry, name: str) -> Pooled | None:
    """A utility figure: mIoU pooled (``miou``); mA and OA, whose per-scene outcomes rows do not keep,
    as the mean over seeds without an interval."""
    if name == "miou":
        return miou(entry)
    stat = entry.metric("utility", name)
    return None if stat is None else _unpooled(stat, _NOT_KEPT.get(name, "per-scene outcomes"))
