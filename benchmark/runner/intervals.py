"""The 95 % intervals attached to rows: Wilson for plate proportions, a scene bootstrap for means.

Scenes are the independent units: restoration scores are bootstrapped over per-scene values,
segmentation scores (pooled confusion matrices, not means) by resampling whole scenes and
recomputing the pooled score. The interval functions themselves are `benchmark.results.stats`.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence

import numpy as np
import torch

from benchmark.results import stats
from benchmark.results.plate_scoring import PlateOutcome
from benchmark.results.schema import Row
from benchmark.codesign.utility.scoring import scores

N_RESAMPLES = 2000


def plate_intervals(row: Row, outcomes: Sequence[PlateOutcome]) -> None:
    """Wilson intervals of plate_acc and plate_det, scene-bootstrap interval of plate_cer."""
    n = len(outcomes)
    if n == 0:
        return
    hits = {"plate_acc": sum(o.correct for o in outcomes), "plate_det": sum(o.detected for o in outcomes)}
    for name in hits:
        if name in row.metrics:
            row.set_interval(name, *stats.wilson_interval(int(hits[name]), n), "wilson")
    if "plate_cer" in row.metrics:
        by_scene: dict[str, list[float]] = {}
        for o in outcomes:
            by_scene.setdefault(o.scene, []).append(o.cer)
        # CER is a mean over plates; scenes are resampled with their plates.
        low, high = _pooled_bootstrap([np.array([sum(v), len(v)]) for v in by_scene.values()],
                                      lambda s: float(s[0] / s[1]), row.seed)
        row.set_interval("plate_cer", low, high, "bootstrap")


def scene_intervals(row: Row, per_image: Mapping[str, Sequence[float]], seed: int) -> None:
    """Scene-bootstrap intervals of the row's metrics that are means of `per_image` values."""
    for name, values in per_image.items():
        if name in row.metrics and len(values) > 0 and all(np.isfinite(values)):
            row.set_interval(name, *stats.bootstrap_mean_interval(list(values), n_resamples=N_RESAMPLES, seed=seed),
                             "bootstrap")


def utility_intervals(row: Row, per_scene_confusion: torch.Tensor) -> None:
    """Scene-bootstrap intervals of miou, mean_acc and overall_acc from (N, C, C) confusion matrices."""
    for name in ("miou", "mean_acc", "overall_acc"):
        if name in row.metrics and len(per_scene_confusion):
            row.set_interval(name, *pooled_score_interval(per_scene_confusion, name, row.seed), "bootstrap")


def pooled_score_interval(per_scene_confusion: torch.Tensor, name: str, seed: int) -> tuple[float, float]:
    """Scene-bootstrap 95 % interval of the pooled score ``name`` (miou, mean_acc or overall_acc) from
    (N, C, C) per-scene confusion matrices: scenes resampled, their matrices summed, the score recomputed."""
    parts = [c.double().numpy() for c in per_scene_confusion]
    return _pooled_bootstrap(parts, lambda conf: _score(conf, name), seed)


def _score(confusion: np.ndarray, name: str) -> float:
    value = scores(torch.from_numpy(confusion))[name]
    assert isinstance(value, float)
    return value


def _pooled_bootstrap(parts: list[np.ndarray], statistic, seed: int) -> tuple[float, float]:
    """Percentile interval (95 %) of statistic(sum of parts) over scenes resampled with replacement."""
    stacked = np.stack(parts)
    rng = np.random.default_rng(seed)
    draws = rng.integers(0, len(parts), size=(N_RESAMPLES, len(parts)))
    values = np.array([statistic(stacked[d].sum(axis=0)) for d in draws])
    values = values[np.isfinite(values)]
    low, high = np.quantile(values, [0.025, 0.975])
    return float(min(low, high)), float(max(low, high))
