"""The run's default attack set: the standard ensemble, chosen from measurements.

``PROPOSED_ENSEMBLE`` is what the rule of ``benchmark.results.ensemble_choice`` (``keeps``) selects on the
published quick entries (docs/ensemble.md, written by ``python -m benchmark.studies.ensemble_choice_study``;
tests/benchmark/results/test_ensemble_choice.py recomputes it, so it cannot drift from the entries).
``MEASURED_ADDITIONS`` (restorers) and ``MEASURED_READERS`` are attackers newer than those entries, added on
measurement; fresh runs of the five privacy lenses with all of them and the cascade gave the rule its next
choice, ``RUN_PROPOSAL``. ``STANDARD_ENSEMBLE`` (that choice and the ``raw`` reference) is what a run
measures unless told otherwise (``benchmark.runner.runner.standard_attackers``).
"""

from __future__ import annotations

from benchmark.results.schema import CASCADE_PREFIX, cascade_name, chain_parts

__all__ = ["CASCADE", "CASCADE_PREFIX", "LEARNED_READER", "MEASURED_ADDITIONS", "MEASURED_READERS",
           "PROPOSED_ENSEMBLE", "RUN_PROPOSAL", "STANDARD_ENSEMBLE", "chain_parts"]

# What the rule selects on the published quick entries (see the module docstring and DOCS); the test
# recomputes it from leaderboard/entries/*quick*.json.
PROPOSED_ENSEMBLE: tuple[str, ...] = (
    "demosaic-vng", "demosaic-vng>lpdr-oracle", "learned-reader", "lpdr", "lpdr-oracle", "nafnet-known-pairs",
    "nafnet-known-pairs>lpdr-oracle", "richardson-lucy-known-psf", "richardson-lucy-known-psf>lpdr",
    "training-adversary", "training-adversary>lpdr-oracle", "wiener-known-psf", "wiener-known-psf>lpdr-oracle")

LEARNED_READER = "learned-reader"
# Restorers the published entries predate, added because they were measured stronger than every restorer
# of those entries on the same scenes (leaderboard/studies/known_psf_restorers.json): the family-trained
# known-PSF restorer, which needs no per-lens fit, and the paper's plate reader after it.
MEASURED_ADDITIONS: tuple[str, ...] = ("nafnet-known-psf", "nafnet-known-psf>lpdr-oracle")
# Readers the published entries predate, added because, on those entries' own plates (paired by plate
# id, leaderboard/studies/psf_reader.json), adding them raises the ensemble's plates read from 32 px by
# more than the rule's 1 point: a reader of the Wiener estimate of the known lens, pre-trained once across the
# lens family on such estimates, which needs no per-lens fit (docs/modelling.md).
MEASURED_READERS: tuple[str, ...] = ("learned-reader-psf",)
# A reader named "cascade:<reader>" runs after every other chain, only on the plates none of them read
# (benchmark.runner.cascade): the maximum-likelihood reader costs seconds a plate.
CASCADE: tuple[str, ...] = (cascade_name("ideal-observer"),)
# The rule re-applied to the full cross product (seed 0) of the five privacy lenses: every attacker that runs by
# default, every reader after every restorer, and the cascade (leaderboard/studies/cross_product, kept in git;
# leaderboard/studies/run_pairing.json "proposal", `python -m benchmark.studies.run_pairing_study --run ...`;
# docs/ensemble.md): the chains whose removal moved some lens's ensemble past the rule's thresholds, the paper's
# lpdr on the sensor image and after the strongest restorer, then the chains that read plates only together,
# added cheapest per point first (``complete_ensemble``) until dropping all the others moves no lens past
# the thresholds, with the restorers they read. In the order a run evaluates them, the cascade last.
# tests/benchmark/runner/test_standard_ensemble.py recomputes it from the kept runs.
RUN_PROPOSAL: tuple[str, ...] = (
    "demosaic-vng", "gray-world", "identity", "nafnet-generic", "nafnet-known-psf", "nafnet-known-psf-tuned",
    "training-adversary", "wiener-known-psf",
    "demosaic-vng>learned-reader", "gray-world>learned-reader", "nafnet-known-psf>learned-reader",
    "wiener-known-psf>learned-reader",
    "demosaic-vng>learned-reader-psf", "gray-world>learned-reader-psf", "identity>learned-reader-psf",
    "nafnet-generic>learned-reader-psf", "training-adversary>learned-reader-psf", "wiener-known-psf>learned-reader-psf",
    "lpdr", "nafnet-known-psf>lpdr", *CASCADE)
# The run's default chains: the rule's, with the uncorrected image as a reference restorer (no chain reads it).
STANDARD_ENSEMBLE: tuple[str, ...] = RUN_PROPOSAL[:-len(CASCADE)] + ("raw",) + CASCADE
