"""The run's default attack set: the standard ensemble, chosen from measurements.

``PROPOSED_ENSEMBLE`` is what the rule of ``benchmark.results.ensemble_choice`` (``keeps``) selects on the
published quick entries (docs/ensemble.md, written by ``python -m benchmark.studies.ensemble_choice_study``;
tests/benchmark/results/test_ensemble_choice.py recomputes it, so it cannot drift from the entries).
``STANDARD_ENSEMBLE`` is what a run measures unless told otherwise (``benchmark.runner.runner.standard_attackers``).
"""

from __future__ import annotations

__all__ = ["LEARNED_READER", "PROPOSED_ENSEMBLE", "STANDARD_ENSEMBLE"]

# What the rule selects on the published quick entries (see the module docstring and DOCS); the test
# recomputes it from leaderboard/entries/*quick*.json.
PROPOSED_ENSEMBLE: tuple[str, ...] = (
    "demosaic-vng", "demosaic-vng>lpdr-oracle", "learned-reader", "lpdr", "lpdr-oracle", "nafnet-known-pairs",
    "nafnet-known-pairs>lpdr-oracle", "richardson-lucy-known-psf", "richardson-lucy-known-psf>lpdr",
    "training-adversary", "training-adversary>lpdr-oracle", "wiener-known-psf", "wiener-known-psf>lpdr-oracle")

LEARNED_READER = "learned-reader"
# The run's default chains: the proposal and the uncorrected image as a reference restorer. The learned
# reader is always in it (the rule keeps it wherever entries hold it) and stays last of the readers, the
# order the published entries' runs evaluated their chains in.
STANDARD_ENSEMBLE: tuple[str, ...] = tuple(c for c in PROPOSED_ENSEMBLE if c != LEARNED_READER) + (LEARNED_READER, "raw")
