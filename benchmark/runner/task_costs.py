"""Measured task costs: what each computed task took, and estimates for planned tasks from them.

Every computed task leaves `cost.json` in its result folder (`tasks.execute`): its wall time in
seconds, what work it was (its signature: kind, lens, attackers, profile settings, scenes,
device) and where and when it was measured (machine, device, threads, date, commit). A dry run
estimates a planned task as the median wall time of the measurements in the cache with the same
signature (any seed, any earlier run or commit); with none, as the shipped table of measured costs
(`benchmark.store.measured_costs`, from docs/costs.md) gives that kind of task for the profile, naming
the machine and date it was measured on; with neither it says "unknown", never a guess.
"""

from __future__ import annotations

import datetime as _dt
import json
import logging
import platform
import statistics
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import torch

from benchmark.store import measured_costs
from benchmark.store.cache import atomic_write_text, config_hash
from benchmark.runner.planning import Task
from benchmark.store.provenance import describe_device, git_commit
from benchmark.runner.config import RunConfig

log = logging.getLogger(__name__)

COST_FILE = "cost.json"


def signature(task: Task, cfg: RunConfig) -> dict[str, Any]:
    """What makes two tasks the same work, whatever their seed or run: kind, lens, attackers, the
    profile's full settings (by hash), scenes and device."""
    return {"kind": task.kind, "lens": task.lens, "restorers": [r.identity for r in task.restorers],
            "readers": [r.identity for r in task.readers], "profile": cfg.profile.name,
            "profile_hash": config_hash(cfg.profile.to_dict()), "scenes": cfg.scenes, "device": cfg.device,
            # the chains an evaluation measures (absent: the full cross product, as older records hold)
            **({"chains": list(cfg.chains)} if cfg.chains is not None and task.kind == "evaluate" else {})}


def record(folder: Path, task: Task, cfg: RunConfig, wall_s: float) -> None:
    """Write the task's `cost.json` into its result folder `folder`."""
    measured = {"wall_s": wall_s, "signature": signature(task, cfg), "task": task.key,
                "machine": platform.node(), "device": describe_device(cfg.device),
                "threads": torch.get_num_threads(), "commit": git_commit(),
                "date": _dt.datetime.now(_dt.timezone.utc).isoformat(timespec="seconds")}
    atomic_write_text(Path(folder) / COST_FILE, json.dumps(measured, indent=1) + "\n")


def recorded(folder: Path) -> float | None:
    """The wall time (s) recorded for the task whose result folder is `folder`, or None."""
    try:
        return float(json.loads((Path(folder) / COST_FILE).read_text())["wall_s"])
    except (OSError, ValueError, KeyError, TypeError):
        return None


def measurements(cache_dir: Path) -> list[dict[str, Any]]:
    """Every task cost recorded in the cache (`<cache>/tasks/<run>/<task>/cost.json`); unreadable ones skipped."""
    found = []
    for path in sorted(Path(cache_dir).glob(f"tasks/*/*/{COST_FILE}")):
        try:
            data = json.loads(path.read_text())
            wall_s, sig = float(data["wall_s"]), data["signature"]
            if not isinstance(sig, dict):
                raise TypeError("signature is not an object")
        except (OSError, ValueError, KeyError, TypeError) as exc:
            log.debug("skipping unreadable task cost %s: %s", path, exc)
            continue
        found.append({**data, "wall_s": wall_s, "path": str(path)})
    return found


@dataclass(frozen=True)
class Estimate:
    """A planned task's cost: median wall time (s) of `n` matching measurements in the cache; with
    none (n = 0), the shipped table's figure (`table` set: `seconds` None when the task is installed
    from the package, `together` when the figure is one for a group of such tasks), else None."""

    seconds: float | None
    n: int
    table: measured_costs.Quote | None = None

    @property
    def installed(self) -> bool:
        return self.n == 0 and self.table is not None and self.table.seconds is None

    @property
    def together(self) -> bool:
        return self.n == 0 and self.table is not None and self.table.together

    def text(self) -> str:
        if self.n:
            return f"~{self.seconds:.1f} s (median of {self.n} measured)"
        if self.table is None:
            return "unknown (no measurement of this task with this profile in the cache or the shipped table)"
        if self.installed:
            return "installed from the package (not measured apart)"
        group = " for all such fits together" if self.together else ""
        return f"~{self.seconds:.0f} s{group} (measured on {self.table.machine}, {self.table.date})"


def estimate(task: Task, cfg: RunConfig, measured: list[dict[str, Any]], attackers: str | None = None
             ) -> Estimate:
    """The median measured wall time of tasks with this task's signature in the cache; with none, the
    shipped table's figure for its kind (`attackers`: "standard", "all-chains" or None for attackers
    named, as `measured_costs.quote` takes it; an evaluation's figure holds only for its attackers)."""
    wanted = signature(task, cfg)
    times = [m["wall_s"] for m in measured if m["signature"] == wanted]
    if times:
        return Estimate(statistics.median(times), len(times))
    if cfg.device != "cpu" or cfg.scenes != "synthetic":
        return Estimate(None, 0)
    restorer = task.restorers[0].name if task.kind == "fit" and task.restorers else None
    quote = measured_costs.quote(cfg.profile.name, task.kind, task.seed, task.lens, restorer, attackers)
    if quote is not None and quote.seconds is not None:
        quote = quote if cfg.profile.to_dict() == _shipped_profile(cfg.profile.name) else None
    return Estimate(quote.seconds if quote else None, 0, quote)


def _shipped_profile(name: str) -> dict[str, Any] | None:
    """The settings of the built-in profile `name` (the table's figures hold only for them)."""
    from benchmark.store.profiles import PROFILES
    return PROFILES[name].to_dict() if name in PROFILES else None


def total(estimates: list[tuple[int, str, Estimate]]) -> Total:
    """The sum over the (seed, lens, estimate) of the tasks to compute: a group figure (`together`)
    counted once per seed and lens, work shared by the lenses (`once_per_seed`) once per seed,
    installed tasks and tasks with no figure counted apart."""
    seconds, unknown, installed = 0.0, 0, 0
    machines: set[tuple[str, str | None]] = set()
    groups: set[tuple[int, str, float]] = set()
    for seed, lens, e in estimates:
        if e.installed:
            installed += 1
            continue
        if e.seconds is None:
            unknown += 1
            continue
        if e.table is not None and e.n == 0:
            machines.add((e.table.machine, e.table.date))
        shared = e.n == 0 and e.table is not None and e.table.once_per_seed
        if e.together or shared:
            group = (seed, "" if shared else lens, e.seconds)
            if group in groups:
                continue
            groups.add(group)
        seconds += e.seconds
    return Total(seconds, unknown, installed, tuple(sorted(machines, key=str)))


@dataclass(frozen=True)
class Total:
    """A plan's estimated seconds, the tasks with no figure and those installed from the package, and
    (machine, date) of every shipped-table figure in it."""

    seconds: float
    unknown: int
    installed: int
    machines: tuple[tuple[str, str | None], ...]
