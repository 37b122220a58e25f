"""Which code made a cached or shipped fit: a version in the fit's key, and a pin on the sources it ran.

A fitted attacker's weights are cached (and some shipped) under a key of what was fitted: budget, lens or
lens family, data and seed. The whole code version is not in it (it changes with every edit, and a shipped
fit would never be found again), so an edit to the training code would leave the old weights in use. The key
therefore also holds `FIT_CODE[attack].version` (from version 2 on: version 1 adds nothing, so the fits made
before it keep their keys), and tests/attacks/training/test_fit_code.py pins a digest of every source the
fit's module imports, transitively, in ``attacks``, ``common`` and ``lenses`` (their syntax trees without
docstrings, as ``benchmark.store.provenance.source_digest`` reads them). When those sources change the test
fails: raise the version if the change alters what is fitted (the fits are then made again, and shipped ones
must be shipped again), else renew the pin. The pins were first set on 2026-12-05 over the sources of that day;
each shipped fit's provenance names the commit it was made at.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

__all__ = ["FIT_CODE", "FitCode", "versioned_key"]


@dataclass(frozen=True)
class FitCode:
    """The module whose import closure fits the attacker, the version of that code, and the closure's digest."""

    module: str
    version: int
    pinned: str


FIT_CODE: dict[str, FitCode] = {
    "learned-reader": FitCode("attacks.readers.learned_reader", 1,
                              "12c70efbf0280b1fc65f39968066955cbfedc2cdeb09d4ff51604b11b59eaf25"),
    "learned-reader-psf": FitCode("attacks.readers.learned_reader_psf", 1,
                                  "648ad2c61de5fd7f303fe3eb3aeea6efa85b00042b21ebaef9bf176ad82d0624"),
    "nafnet-known-pairs-tuned": FitCode("attacks.restorers.nafnet_known_pairs", 2,
                                        "f5f3744d7e37dedf6d4d1656f0da7e2724498a707d0f1d724563b7eae8e469a5"),
    "nafnet-known-psf-tuned": FitCode("attacks.restorers.nafnet_known_pairs", 2,
                                      "f5f3744d7e37dedf6d4d1656f0da7e2724498a707d0f1d724563b7eae8e469a5"),
    "nafnet-known-psf": FitCode("attacks.restorers.nafnet_known_psf", 1,
                                "51b96cadde29c6635609aad1f60c312369f94aafe09b68eabb48c9410d7d199e"),
}


def versioned_key(attack: str, key: dict[str, Any]) -> dict[str, Any]:
    """`key` with the version of the code that fits `attack` (unchanged at version 1)."""
    version = FIT_CODE[attack].version
    return dict(key) if version == 1 else {**key, "fit_code": version}
