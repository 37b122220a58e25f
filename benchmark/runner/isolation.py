"""What keeps one attacker from reaching another's inputs, outputs or run: private copies of what it
is handed, and the failure boundary around every call into a plugin.

Torch has no read-only tensors, so every batch handed to an attacker is a copy it owns: a restorer
that writes into its input (``s.zero_()``) would otherwise change the sensor images every later
attacker sees, and a reader that writes into a restorer's output would change what the next reader
reads. What an attacker returns is checked and copied by the evaluation before it is kept, so the
attacker cannot change it afterwards either. Each attacker also gets its own fit context: its own
copy of the lens and of its co-design adversary (an attacker may move their parameters).
"""

from __future__ import annotations

import copy
import dataclasses
import logging
from collections.abc import Callable
from typing import TypeVar

import torch

import attacks
from benchmark.runner.budget import time_budget
from benchmark.results.schema import RowError

log = logging.getLogger(__name__)
T = TypeVar("T")


def private(batch: torch.Tensor, device: str) -> torch.Tensor:
    """A copy of `batch` on `device` that shares no memory with it (what an attacker is handed)."""
    return batch.to(device, copy=True)


def own_context(ctx: attacks.FitContext) -> attacks.FitContext:
    """A fit context for one attacker: its own copy of the lens and the adversary (one deep copy, so the
    copied lens still holds the copied adversary). Training pairs need no copy: `train_pairs()` makes
    fresh tensors at every call (benchmark.runner.sensing.train_pairs_factory)."""
    lens, adversary = copy.deepcopy((ctx.lens, ctx.adversary))
    return dataclasses.replace(ctx, lens=lens, adversary=adversary)


def attempt(attacker: str, stage: str, work: Callable[[], T], budget_s: float | None = None) -> T | RowError:
    """Run `work` within `budget_s` seconds (None: no limit); anything it raises, or running out of
    time, becomes the RowError of `attacker` at `stage` (and is logged).

    Anything means any BaseException but the user's own Ctrl-C (KeyboardInterrupt): a plugin's
    ``raise SystemExit(3)`` or ``sys.exit()`` would otherwise end the run with nothing written."""
    try:
        with time_budget(budget_s, f"{attacker} ({stage})"):
            return work()
    except KeyboardInterrupt:
        raise
    except BaseException as exc:  # noqa: BLE001 - a broken plugin must not take the run down
        log.warning("attacker %r failed at %s: %s: %s", attacker, stage, type(exc).__name__, exc)
        return RowError(attacker, stage, shortened(f"{type(exc).__name__}: {exc}"))


# A row's error says what failed in a sentence or two; a library's own dump (torch's dispatcher lists
# every backend, kilobytes of it) goes to the log whole.
MAX_ERROR_CHARS = 500


def shortened(message: str, limit: int = MAX_ERROR_CHARS) -> str:
    """`message` cut to `limit` characters, saying how much more the log holds."""
    if len(message) <= limit:
        return message
    return f"{message[:limit].rstrip()} ... ({len(message) - limit} more characters in the log)"


def describe(attacker: attacks.Attack) -> dict | RowError:
    """The attacker's `describe()` (its settings, stored with its rows), or the RowError of its
    raising or returning something other than a dict (stage "load": it cannot be set up)."""
    def checked() -> dict:
        described = attacker.describe()
        if not isinstance(described, dict):
            raise TypeError(f"returned {type(described).__name__}; expected a dict")
        return described
    result = attempt(attacker.name, "load", checked)
    if isinstance(result, RowError):
        return RowError(result.attacker, result.stage, f"{attacker.name}.describe() failed: {result.message}")
    return result
