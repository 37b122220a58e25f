"""Rows of one task, built only through `benchmark.schema.Row`, with their settings registered.

Every row points at the full settings that made it (lens spec, profile, scenes, seed and the
attackers' `describe()`) by hash; the task keeps the settings so that results.json can carry
them once per hash.
"""

from __future__ import annotations

from typing import Any

from benchmark.run_config import RunConfig
from benchmark.schema import Row, RowError, settings_hash


class RowBuilder:
    """Makes the rows of one (lens, seed) and collects the settings they point at.

    Args:
        cfg: The run.
        lens: Lens name of the rows (`sharp` for the sharp reference).
        seed: Seed of the rows.
        base_settings: What every row of this lens and seed shares (lens spec, profile, scenes, seed).
        provenance: Run-wide provenance (benchmark.provenance.provenance).
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
