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

Each lens and seed is computed in a process of its own (`lens_processes`: ``publish --compute-only --lens L
--seeds S``), one after another, so that no process holds more than one lens-seed's memory (one of the quick
profile peaks at about 6.5 GiB, a lens's three seeds in one process at 7.5 GiB, the whole board in one
process past 8 GiB); its tasks land in the cache, and the publishing process then assembles every lens
from the cache and replaces the entries. Each process's
wall time, peak resident memory, exit status and the machine's load go to ``<out>/publish_log.jsonl``
(appended: a publish resumed in a later sitting adds its parts), so the whole board's compute time is
measured even when it ran in several sittings (`log_summary`).

The command itself lives in `benchmark.cli` (it runs `benchmark.api.run`, above this layer); this
module holds what it computes.
"""

from __future__ import annotations

import datetime as _dt
import json
import os
import statistics
import subprocess
import sys
import time
from collections.abc import Iterable, Sequence
from dataclasses import asdict, dataclass
from pathlib import Path
from typing import Any, Protocol

from tqdm.auto import tqdm

__all__ = ["CACHED_S", "EtaBar", "LensPart", "Weights", "lens_command", "lens_processes", "lens_seed_parts",
           "log_summary", "read_log", "summary", "task_weights"]

LOG_NAME = "publish_log.jsonl"

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


@dataclass(frozen=True)
class LensPart:
    """One lens's process of a publish: what it computed, how long it took and how much memory it held."""

    lens: str
    code_version: str
    started: str  # ISO time, UTC
    to_compute: int  # tasks of the lens (and shared ones) not in the cache when it started
    estimate_s: float  # their estimated seconds
    wall_s: float
    peak_rss_mib: float  # the process's own peak resident memory (VmHWM, polled)
    returncode: int  # 0: every row; 1: some rows failed (written as failed rows); else the process died
    load_before: tuple[float, float, float]
    load_after: tuple[float, float, float]
    seed: int | None = None  # the seed it ran; None: every seed of the publish in one process

    @property
    def died(self) -> bool:
        """Killed by a signal or exited with a status other than 0 (every row) and 1 (some rows failed)."""
        return self.returncode not in (0, 1)


def lens_seed_parts(planned: Sequence[_Planned], lenses: Sequence[str], seeds: Sequence[int], weights: Weights
                    ) -> list[tuple[str, int, int, float]]:
    """The processes of a publish, in order: (lens, seed, tasks to compute, their estimated seconds) for each
    lens (in the order given) and seed with a task not in the cache; a task shared by the lenses (sharp
    scenes, spectrum) counts in the first process of its seed, which computes it."""
    shared: set[str] = set()
    parts = []
    for lens in lenses:
        for seed in seeds:
            tasks = [t for t in planned if not t.cached and t.seed == seed and t.lens in (lens, "")
                     and t.key not in shared]
            shared.update(t.key for t in tasks if not t.lens)
            if tasks:
                parts.append((lens, seed, len(tasks), sum(weights.seconds[t.key] for t in tasks)))
    return parts


def lens_command(lens: str, profile: str, seeds: Sequence[int], device: str, out: Path) -> list[str]:
    """The command line of one lens's process: compute and cache its tasks, publish nothing."""
    return [sys.executable, "-m", "benchmark", "publish", "--compute-only", "--lens", lens, "--profile", profile,
            "--seeds", ",".join(str(s) for s in seeds), "--device", device, "--out", str(out)]


def _high_water_mib(pid: int) -> float | None:
    """A live process's peak resident memory so far (VmHWM, MiB); None once it is gone."""
    try:
        for line in Path(f"/proc/{pid}/status").read_text().splitlines():
            if line.startswith("VmHWM:"):
                return int(line.split()[1]) / 1024
    except OSError:
        return None
    return None


def _wait(process: subprocess.Popen) -> tuple[int, float]:
    """Wait for a child; its exit status (negative: the signal that killed it) and its own peak resident
    MiB, polled from /proc while it runs (getrusage's figure would hold the parent's memory, which the child
    shared until its exec), every 0.05 s in its first 5 s, then every second."""
    peak, t0 = 0.0, time.perf_counter()
    while True:
        pid, status = os.waitpid(process.pid, os.WNOHANG)
        if pid:
            process.returncode = os.waitstatus_to_exitcode(status)
            return process.returncode, peak
        peak = max(peak, _high_water_mib(process.pid) or 0.0)
        time.sleep(0.05 if time.perf_counter() - t0 < 5 else 1.0)


def lens_processes(parts: Sequence[tuple[str, int, int, float]], profile: str, device: str, out: Path,
                   code_version: str, echo: Any = print) -> list[LensPart]:
    """Compute each lens-seed of `parts` ((lens, seed, tasks to compute, estimated seconds), in order) in a
    process of its own, one at a time, logging each to ``out/publish_log.jsonl``. Stops at the first process that
    died (a signal or an exit status other than 0 and 1): what it finished is cached; the same command
    resumes. Returns the parts run."""
    out.mkdir(parents=True, exist_ok=True)
    done: list[LensPart] = []
    left = sum(p[3] for p in parts)
    for i, (lens, seed, count, estimate) in enumerate(parts, 1):
        echo(f"[{i}/{len(parts)}] {lens} seed {seed}: {count} tasks to compute, about {estimate / 60:.0f} min "
             f"(all lenses left: about {left / 60:.0f} min)")
        started, load_before, t0 = _dt.datetime.now(_dt.timezone.utc), os.getloadavg(), time.perf_counter()
        process = subprocess.Popen(lens_command(lens, profile, [seed], device, out / "lenses" / f"{lens}-s{seed}"))
        try:
            code, peak = _wait(process)
        except BaseException:
            process.terminate()
            raise
        part = LensPart(lens, code_version, started.isoformat(timespec="seconds"), count, round(estimate, 1),
                        round(time.perf_counter() - t0, 1), round(peak, 1), code, tuple(load_before),
                        tuple(os.getloadavg()), seed)
        with open(out / LOG_NAME, "a") as f:
            f.write(json.dumps(asdict(part)) + "\n")
        done.append(part)
        left -= estimate
        echo(f"[{i}/{len(parts)}] {lens} seed {seed}: {part.wall_s / 60:.1f} min, peak {part.peak_rss_mib / 1024:.2f} GiB"
             + (f"; the process died (exit status {code})" if part.died else ""))
        if part.died:
            break
    return done


def read_log(out: Path, code_version: str | None = None) -> list[LensPart]:
    """The lens parts logged in ``out/publish_log.jsonl`` (of one code version when given); a line that is
    not a part (a torn write) is skipped."""
    path = out / LOG_NAME
    if not path.exists():
        return []
    parts = []
    for line in path.read_text().splitlines():
        try:
            d = json.loads(line)
            d["load_before"], d["load_after"] = tuple(d["load_before"]), tuple(d["load_after"])
            part = LensPart(**d)
        except (ValueError, TypeError, KeyError):
            continue
        if code_version is None or part.code_version == code_version:
            parts.append(part)
    return parts


def log_summary(parts: Sequence[LensPart]) -> str:
    """The whole publish's compute so far: seconds summed over its lens processes, their sittings (days
    they started on) and the highest peak; what the budget is compared with."""
    if not parts:
        return "no lens process logged"
    wall = sum(p.wall_s for p in parts)
    days = sorted({p.started[:10] for p in parts})
    loads = [max(p.load_before[0], p.load_after[0]) for p in parts]
    return (f"{len(parts)} processes, {wall:.0f} s ({wall / 3600:.2f} h) in all, started "
            f"{', '.join(days)}; peak {max(p.peak_rss_mib for p in parts) / 1024:.2f} GiB; "
            f"1-min load {min(loads):.1f}-{max(loads):.1f}")
