"""Re-publish the leaderboard in one command: ``python -m benchmark publish``.

One run of every registered lens (or those named) at the profile's seeds with the standard ensemble
(`benchmark.runner.defaults.STANDARD_ENSEMBLE`), whose entries then replace the published ones
whole (`leaderboard.publish(..., replace=True)`): nothing measured by an older version stays beside
the new rows. The run's tasks are cached as they finish, so the same command after an interruption
resumes where it stopped, also after a commit that changed only docs, tests or the publishing code
(the run's folder is keyed by `benchmark.store.provenance.code_version`, not by the commit).

Progress is a bar over the plan's *estimated seconds* (`benchmark.runner.task_costs`: the median
measured cost of the same work in the cache, else the shipped table): each finished task advances it
by its estimate, so its rate is estimated seconds per real second and its ETA calibrates itself to
this machine's speed and load as the run goes. A task with no estimate counts as the median estimate
of its kind in the plan (of the whole plan when its kind has none); the plan says how many those are.

The command itself lives in `benchmark.cli` (it runs `benchmark.api.run`, above this layer); this
module holds what it computes.
"""

from __future__ import annotations

import statistics
from collections.abc import Iterable, Sequence
from dataclasses import dataclass
from typing import Any, Protocol

from tqdm.auto import tqdm

__all__ = ["CACHED_S", "EtaBar", "Weights", "summary", "task_weights"]

# A cached task is read back, not computed: it advances the bar by (about) nothing.
CACHED_S = 0.5


class _Planned(Protocol):
    key: str
    kind: str
    seed: int
    lens: str
    cached: bool
    estimate: Any


@dataclass(frozen=True)
class Weights:
    """Seconds each planned task is expected to take (`seconds`, by task key), and how many of them had
    no measured estimate (`guessed`: counted at their kind's median)."""

    seconds: dict[str, float]
    guessed: int

    @property
    def total(self) -> float:
        return sum(self.seconds.values())


def task_weights(planned: Sequence[_Planned]) -> Weights:
    """Expected seconds per task of a plan (`benchmark.api.Plan.tasks`): cached tasks `CACHED_S`, tasks
    with an estimate their estimate, installed ones `CACHED_S`, the rest their kind's median estimate."""
    known: dict[str, float] = {}
    groups: dict[tuple, list[str]] = {}  # a figure for a group of tasks (task_costs.total) is shared among them
    for t in planned:
        if not t.cached and t.estimate.seconds is not None:
            known[t.key] = float(t.estimate.seconds)
            quote = t.estimate.table if t.estimate.n == 0 else None
            if quote is not None and (quote.together or quote.once_per_seed):
                group = (t.seed, "" if quote.once_per_seed else t.lens, t.kind, quote.seconds)
                groups.setdefault(group, []).append(t.key)
    for keys in groups.values():
        for key in keys:
            known[key] /= len(keys)
    by_kind: dict[str, list[float]] = {}
    for t in planned:
        if t.key in known:
            by_kind.setdefault(t.kind, []).append(known[t.key])
    overall = statistics.median(known.values()) if known else 1.0
    seconds, guessed = {}, 0
    for t in planned:
        if t.cached or t.estimate.installed:
            seconds[t.key] = CACHED_S
        elif t.key in known:
            seconds[t.key] = known[t.key]
        else:
            seconds[t.key] = statistics.median(by_kind[t.kind]) if t.kind in by_kind else overall
            guessed += 1
    return Weights(seconds, guessed)


class EtaBar:
    """A progress bar over estimated seconds; call it with each finished task (``api.run(on_task=...)``)."""

    def __init__(self, weights: Weights, desc: str = "publish", **tqdm_options: Any) -> None:
        self.weights = weights
        self.done: list[str] = []
        self.bar = tqdm(total=round(weights.total, 1), desc=desc, unit="est-s", unit_scale=False, **tqdm_options)

    def __call__(self, task: Any) -> None:
        self.done.append(task.key)
        self.bar.set_postfix_str(task.key, refresh=False)
        self.bar.update(round(self.weights.seconds.get(task.key, 0.0), 1))

    def close(self) -> None:
        self.bar.close()


def summary(planned: Iterable[_Planned], weights: Weights) -> str:
    """One line: tasks to compute and cached, the estimated total and how many tasks had no estimate."""
    planned = list(planned)
    compute = sum(not t.cached for t in planned)
    text = (f"{len(planned)} tasks ({compute} to compute, {len(planned) - compute} cached); estimated "
            f"{weights.total / 60:.0f} min from measured task costs")
    if weights.guessed:
        text += f" ({weights.guessed} tasks with no measurement counted at their kind's median)"
    return text
