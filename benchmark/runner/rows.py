"""Rows of one task, built only through `benchmark.results.schema.Row`, with their settings registered.

Every row points at the full settings that made it (lens spec, profile, scenes, seed and the
attackers' `describe()`) by hash; the task keeps the settings so that results.json can carry
them once per hash.

The rows' per-unit outcomes (`schema.Units`) are built here from what the measurement returns:
``scene_units`` (per-scene PSNR / SSIM), ``utility_units`` (per-scene per-class intersection and
union counts) and ``plate_units`` (per-plate exact read and character errors). Their ids are the
scenes' names, which depend on scene set, split, run seed and index only, so two lenses of the
same profile and seed are paired on the same scenes and plates.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from typing import Any

import numpy as np
import torch

from benchmark.results.ensemble import WIDTH_VALUE
from benchmark.results.plate_scoring import PlateOutcome
from benchmark.runner.config import RunConfig
from benchmark.scenes import Scene
from benchmark.results.schema import Row, RowError, Units, settings_hash


class RowBuilder:
    """Makes the rows of one (lens, seed) and collects the settings they point at.

    Args:
        cfg: The run.
        lens: Lens name of the rows (`sharp` for the sharp reference).
        seed: Seed of the rows.
        base_settings: What every row of this lens and seed shares (lens spec, profile, scenes, seed).
        provenance: Run-wide provenance (benchmark.store.provenance.provenance).
    """

    def __init__(self, cfg: RunConfig, lens: str, seed: int, base_settings: dict[str, Any],
                 provenance: dict[str, Any]):
        self.cfg, self.lens, self.seed = cfg, lens, seed
        self.base_settings, self.provenance = base_settings, provenance
        self.settings: dict[str, dict[str, Any]] = {}

    def _hash(self, extra: dict[str, Any]) -> str:
        settings = {**self.base_settings, **extra}
        key = settings_hash(settings)
        self.settings[key] = settings
        return key

    def row(self, kind: str, metrics: dict[str, float], *, attack: str | None = None, restorer: str | None = None,
            reader: str | None = None, threat_model: str | None = None, notes: dict[str, str] | None = None,
            settings: dict[str, Any] | None = None) -> Row:
        """An ok row; `settings` adds to the base settings (e.g. {"restorer": describe()})."""
        return Row(kind=kind, lens=self.lens, attack=attack or kind, seed=self.seed, profile=self.cfg.profile.name,
                   scenes=self.cfg.scenes, restorer=restorer, reader=reader, metrics=metrics,
                   threat_model=threat_model, notes=notes or {}, settings_hash=self._hash(settings or {}),
                   provenance=dict(self.provenance))

    def failed(self, kind: str, attack: str, error: RowError, *, restorer: str | None = None,
               reader: str | None = None, settings: dict[str, Any] | None = None) -> Row:
        """A failed row: the error, no metric."""
        return Row.failed(kind, self.lens, attack, self.seed, self.cfg.profile.name, self.cfg.scenes, error,
                          restorer=restorer, reader=reader, settings_hash=self._hash(settings or {}),
                          provenance=dict(self.provenance))


def training_facts(record: Mapping[str, Any] | None) -> tuple[dict[str, float], dict[str, str]]:
    """The lens row's facts from a co-design training record (benchmark.codesign): metric
    ``bound_limited`` (1.0 when the trained mask ended on a coefficient bound, else 0.0) and note
    ``bound_limited_terms`` (the Zernike terms on a bound, e.g. "Z4, Z6"), and note ``trainer_version``
    (the co-design trainer's version: entries of other versions are not merged). Nothing for a lens
    that was not trained, or whose mask has no bounds."""
    if not record or "bound_limited" not in record:
        return {}, {}
    terms = list(record.get("bound_limited_terms") or [])
    version = (record.get("config") or {}).get("version")
    return {"bound_limited": float(bool(record["bound_limited"]))}, (
        ({"bound_limited_terms": ", ".join(terms)} if terms else {})
        | ({"trainer_version": str(version)} if version is not None else {}))


def scene_units(scenes: Sequence[Scene], per_scene: Mapping[str, Sequence[float]]) -> Units:
    """Per-scene values (e.g. {"psnr_db": [...], "ssim": [...]}, one per scene, in `scenes`' order).

    A metric with a non-finite value (an exact copy's infinite PSNR) is left out: its mean is not
    a row metric either."""
    columns = {name: [float(v) for v in values] for name, values in per_scene.items()
               if len(values) == len(scenes) and all(np.isfinite(values))}
    return Units.from_names("scene", [s.name for s in scenes], columns)


def utility_units(scenes: Sequence[Scene], per_scene_confusion: torch.Tensor) -> Units:
    """Per-scene, per-class intersection (true positives) and union (TP + FP + FN) pixel counts
    from the (N, C, C) confusion matrices (rows = ground truth): summing them over any subset of
    scenes and taking the mean of intersection / union over classes with a union gives that
    subset's pooled mIoU exactly (benchmark.codesign.utility.scoring.scores)."""
    if per_scene_confusion.ndim != 3 or per_scene_confusion.shape[0] != len(scenes):
        raise ValueError(f"need one (C, C) confusion matrix per scene, got shape {tuple(per_scene_confusion.shape)} "
                         f"for {len(scenes)} scenes")
    conf = per_scene_confusion.long()
    tp = conf.diagonal(dim1=1, dim2=2)
    union = conf.sum(dim=2) + conf.sum(dim=1) - tp
    return Units.from_names("scene", [s.name for s in scenes],
                            {"intersection": tp.tolist(), "union": union.tolist()})


def plate_units(outcomes: Sequence[PlateOutcome]) -> Units:
    """Per-plate outcomes: ``correct`` (1 when read exactly), ``char_errors`` (edit distance of the
    best read to the truth) and ``width_px`` (the plate's box width, what the ensemble's per-width
    accuracy bins by: benchmark.results.ensemble). A plate's id is ``{scene name}#{k}``, the k-th readable plate scored in
    that scene (or plate window), in the order benchmark.results.plate_scoring.score_scene scores them."""
    seen: dict[str, int] = {}
    names = []
    for o in outcomes:
        k = seen.get(o.scene, 0)
        seen[o.scene] = k + 1
        names.append(f"{o.scene}#{k}")
    return Units.from_names("plate", names, {
        "correct": [int(o.correct) for o in outcomes],
        "char_errors": [int(round(o.cer * len(o.truth))) for o in outcomes],
        WIDTH_VALUE: [int(o.width_px) for o in outcomes]})
