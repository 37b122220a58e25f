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
                              "7854da9a752c1f54d0147ed9094475743badcd1148dca2487a44a566849df71e"),
    "learned-reader-psf": FitCode("attacks.readers.learned_reader_psf", 1,
                                  "f5c23b2c87b28f68272fb32eac46f170b4cf532041d91bb95f65824ac741ab51"),
    "nafnet-known-pairs-tuned": FitCode("attacks.restorers.nafnet_known_pairs", 2,
                                        "791cd8754a638b0d9b5ab6bd0f7f8beeb9baf25a4ad354c70775dfb9d2cf99b3"),
    "nafnet-known-psf-tuned": FitCode("attacks.restorers.nafnet_known_pairs", 2,
                                      "791cd8754a638b0d9b5ab6bd0f7f8beeb9baf25a4ad354c70775dfb9d2cf99b3"),
    "nafnet-known-psf": FitCode("attacks.restorers.nafnet_known_psf", 1,
                                "0c4aa6108c95ac2cf6439121cf45854abea61c7539ea55a92fe6cf4999eb00ca"),
}


def versioned_key(attack: str, key: dict[str, Any]) -> dict[str, Any]:
    """`key` with the version of the code that fits `attack` (unchanged at version 1)."""
    version = FIT_CODE[attack].version
    return dict(key) if version == 1 else {**key, "fit_code": version}
