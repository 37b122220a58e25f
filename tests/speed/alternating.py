"""Timing two or more implementations in one run: a warm-up call each, then rounds in which the runs
take turns, so that all of them see the same load on a shared machine."""

from __future__ import annotations

import time
from collections.abc import Callable
from typing import TypeVar

T = TypeVar("T")


def alternate(runs: dict[str, Callable[[], T]], rounds: int) -> tuple[dict[str, T], dict[str, list[float]]]:
    """Each run's output (from its warm-up call) and its seconds in each of ``rounds`` rounds."""
    outputs = {name: run() for name, run in runs.items()}
    seconds: dict[str, list[float]] = {name: [] for name in runs}
    for _ in range(rounds):
        for name, run in runs.items():
            t0 = time.perf_counter()
            run()
            seconds[name].append(time.perf_counter() - t0)
    return outputs, seconds


def best_seconds(runs: dict[str, Callable[[], object]], rounds: int) -> dict[str, float]:
    """Each run's fastest round (``alternate``)."""
    _, seconds = alternate(runs, rounds)
    return {name: min(s) for name, s in seconds.items()}
