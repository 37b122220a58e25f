"""The shipped table of measured costs (``measured_costs.json``), copied from docs/costs.md.

Per profile: whole runs as measured (command, seconds, machine, date) and, where docs/costs.md
breaks a run down, the seconds of each task kind (by fixed or co-designed lens, by restorer for a
fit, for the attackers it ran only for an evaluation). A dry run quotes them for a task the cache
has no measurement of (`benchmark.runner.task_costs`); the profiles' descriptions take their times
from the runs (`run_text`). Nothing here is estimated: a kind without a figure in docs/costs.md is
absent, and a task installed from the package at that seed (the shipped gp lens of seed 0) is
"installed", not measured.
"""

from __future__ import annotations

import functools
import json
from dataclasses import dataclass
from pathlib import Path
from typing import Any

TABLE = Path(__file__).with_name("measured_costs.json")
CODESIGN_MODULE = "benchmark.codesign."  # where co-designed lenses' factories live (pyproject entry points)


@functools.cache
def table() -> dict[str, Any]:
    """The shipped table (see the module docstring)."""
    return json.loads(TABLE.read_text(encoding="utf-8"))


def _minutes(seconds: float) -> str:
    m, s = divmod(round(seconds), 60)
    return f"{m} min {s} s" if m else f"{s} s"


def run_text(profile: str) -> str:
    """The first measured whole run of `profile` in words ("`run --lens gp` (...) took 10 min 59 s on ..."),
    or "" when docs/costs.md measured none."""
    runs = table()["profiles"].get(profile, {}).get("runs", [])
    if not runs:
        return ""
    run = runs[0]
    took = " to ".join(_minutes(s) for s in run["seconds"])
    when = f", {run['date']}" if run.get("date") else ""
    return f"`{run['command']}` ({run['what']}) took {took} on {run['machine']}{when}"


def is_codesigned(lens: str) -> bool | None:
    """True for a registered co-designed lens, False for another registered one, None for a name the
    registry does not know (a spec file, a plugin lens not installed)."""
    from common.plugins import discover  # lazy: entry-point discovery only when a plan asks
    ep = discover("privacy_lens_bench.lenses").get(lens)
    return None if ep is None else ep.value.startswith(CODESIGN_MODULE)


@dataclass(frozen=True)
class Quote:
    """A task's figure from the table: `seconds` (None: installed from the package, not measured), whether
    it was measured `together` with the other tasks of its kind and lens (one figure for the group),
    whether the work is done `once_per_seed` (shared by the lenses: the cache serves the others), and
    where and when it was measured."""

    seconds: float | None
    together: bool
    once_per_seed: bool
    machine: str
    date: str | None


def quote(profile: str, kind: str, seed: int, lens: str = "", restorer: str | None = None,
          attackers: str | None = "standard") -> Quote | None:
    """The table's figure for one planned task, or None when docs/costs.md has none for it.

    `attackers` is what the run evaluates: "standard" (the standard ensemble), "all-chains" (every
    attacker run by default after every restorer) or None (attackers named); an evaluation's figure
    holds only for the attackers it was measured with (the table's "attackers" field)."""
    entry = table()["profiles"].get(profile)
    if entry is None:
        return None
    where = entry.get("tasks_measured_on", {})
    machine, date = where.get("machine", ""), where.get("date")
    for s in entry.get("shipped", []):
        if (s["kind"] == kind and s.get("lens", lens) == lens and s.get("seed", seed) == seed
                and s.get("restorer", restorer) == restorer):
            return Quote(None, False, False, machine, date)
    codesigned = is_codesigned(lens) if lens else None
    wanted = None if codesigned is None else ("co-designed" if codesigned else "fixed")
    candidates = [t for t in entry.get("tasks", []) if t["kind"] == kind
                  and ("lens" not in t or t["lens"] == wanted)
                  and t.get("attackers", attackers) == attackers]
    named = [t for t in candidates if t.get("restorer") == restorer]
    if not named and restorer is not None:
        listed = {t.get("restorer") for t in entry.get("tasks", []) if t["kind"] == kind}
        named = [t for t in candidates if t.get("restorer") == "*" and restorer not in listed]
    if not named:
        return None
    task = named[0]  # a figure measured elsewhere or on another day names its own machine and date
    return Quote(float(task["seconds"]), bool(task.get("together")), bool(task.get("once_per_seed")),
                 task.get("machine", machine), task.get("date", date))
