"""Measured task costs: what each computed task took, and estimates for planned tasks from them.

Every computed task leaves `cost.json` in its result folder (`tasks.execute`): its wall time in
seconds, what work it was (its signature: kind, lens, attackers, profile settings, scenes,
device) and where and when it was measured (machine, device, threads, date, commit). A dry run
estimates a planned task as the median wall time of the measurements in the cache with the same
signature (any seed, any earlier run or commit); with none it says "unknown", never a guess.
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
            "profile_hash": config_hash(cfg.profile.to_dict()), "scenes": cfg.scenes, "device": cfg.device}


def record(folder: Path, task: Task, cfg: RunConfig, wall_s: float) -> None:
    """Write the task's `cost.json` into its result folder `folder`."""
    measured = {"wall_s": wall_s, "signature": signature(task, cfg), "task": task.key,
                "machine": platform.node(), "device": describe_device(cfg.device),
                "threads": torch.get_num_threads(), "commit": git_commit(),
                "date": _dt.datetime.now(_dt.timezone.utc).isoformat(timespec="seconds")}
    atomic_write_text(Path(folder) / COST_FILE, json.dumps(measured, indent=1) + "\n")


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
    """A planned task's cost: median wall time (s) of `n` matching measurements; None when n = 0."""

    seconds: float | None
    n: int

    def text(self) -> str:
        if self.seconds is None:
            return "unknown (no measurement of this task with this profile in the cache)"
        return f"~{self.seconds:.1f} s (median of {self.n} measured)"


def estimate(task: Task, cfg: RunConfig, measured: list[dict[str, Any]]) -> Estimate:
    """The median measured wall time of tasks with this task's signature."""
    wanted = signature(task, cfg)
    times = [m["wall_s"] for m in measured if m["signature"] == wanted]
    return Estimate(statistics.median(times), len(times)) if times else Estimate(None, 0)


def recorded(folder: Path) -> float | None:
    """The wall time (s) recorded for the task whose result folder is `folder`, or None."""
    try:
        return float(json.loads((Path(folder) / COST_FILE).read_text())["wall_s"])
    except (OSError, ValueError, KeyError, TypeError):
        return None
