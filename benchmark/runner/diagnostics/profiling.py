"""Where a run's time goes: per task and per pipeline stage, by cProfile, with peak memory.

``python -m benchmark run ... --profile-time`` profiles every task the run computes (tasks
loaded from the cache cost nothing and are not listed) and writes ``profile.json`` and
``profile.md`` into the run folder. Per task: wall seconds, share of the profiled time,
images/s (the profile's val scenes over the task's whole seconds, for tasks that process them),
peak memory (the process's resident high-water mark from ``getrusage`` and how much the task
raised it; with ``trace_python`` (``--profile-python-memory``) the peak of Python / NumPy allocations
from ``tracemalloc``, off by default because it traces every allocation: it slowed a quick co-design
step from 1.40 to 1.87 s, where cProfile and the sampler together cost 1.31 -> 1.40 s; on CUDA torch's own
``max_memory_allocated``; and, from ``benchmark.runner.diagnostics.memory_sampler``, the sampled resident peak with our
frames on the stack when it was set, so one sees which code holds the memory), the pipeline stages (``STAGES``: inclusive cumulative seconds of the
functions that implement them, their images/s from the call counts, the highest resident memory
sampled while they ran) and the top functions by
cumulative time. Stages nest (a reader's ``read`` includes its segmentation), so their shares
need not add up to 100 %. Under cProfile the Python-level code runs slower; the torch kernels,
where the time goes, do not.

``cost_table`` renders the README's cost table from a profile.
"""

from __future__ import annotations

import contextlib
import cProfile
import json
import os
import pstats
import resource
import sys
import time
import tracemalloc
from collections.abc import Iterator
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import torch

from benchmark.runner.diagnostics.memory_sampler import PeakSampler
from benchmark.runner.planning import Task

__all__ = ["STAGES", "RunProfiler", "Stage", "cost_table", "profiled", "stage_table", "task_scope"]

TOP_FUNCTIONS = 30  # deep enough to show what a stage (e.g. OCR: conv, ONNX run, LSTM tail) spends


@dataclass(frozen=True)
class Stage:
    """A pipeline stage: the functions (path suffix of the file, function name) whose cumulative time
    it is, and whether each call processes the run's val scenes (then images/s = calls x n_val / s)."""

    name: str
    functions: tuple[tuple[str, str], ...]
    per_call_images: bool = False


STAGES: tuple[Stage, ...] = (
    Stage("lens: build or load", (("lenses/__init__.py", "load"),)),
    Stage("scenes: generate", (("benchmark/scenes/loading.py", "load_scenes"),)),
    Stage("utility net: train or load", (("benchmark/codesign/trainer.py", "pretrain_utility"),
                                         ("benchmark/runner/utility_measure.py", "utility_net_for"))),
    Stage("sense (lens forward)", (("benchmark/runner/sensing.py", "sense"),), per_call_images=True),
    Stage("segment (sliding window)", (("benchmark/codesign/utility/scoring.py", "predict"),), per_call_images=True),
    Stage("restorer fit", (("attacks/training/restorer_training.py", "train_restorer"),)),
    Stage("restore", (("benchmark/runner/evaluation.py", "restore_all"),), per_call_images=True),
    Stage("restoration metrics", (("benchmark/runner/evaluation.py", "restoration_metrics"),)),
    Stage("read plates", (("benchmark/runner/evaluation.py", "read_plates"),), per_call_images=True),
    Stage("read: vehicles", (("attacks/readers/lpdr.py", "_vehicles"),)),
    Stage("read: plate detection", (("attacks/readers/lpdr.py", "_detect"),)),
    Stage("read: OCR", (("attacks/readers/plates/ocr.py", "read_plates"),)),
    Stage("privacy bound", (("lenses/bound.py", "bound_row"), ("lenses/bound.py", "bound_curve"))),
    Stage("plate spectrum", (("benchmark/scenes/plate_spectrum.py", "cached_plate_spectrum"),)),
    Stage("pictures", (("benchmark/runner/tasks.py", "_sample_grid"), ("benchmark/runner/tasks.py", "_plate_gallery"))),
)

_ACTIVE: RunProfiler | None = None


def _maxrss_mib() -> float:
    # ru_maxrss is KiB on Linux, bytes on macOS.
    rss = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss
    return rss / (2**20 if sys.platform == "darwin" else 2**10)


class RunProfiler:
    """Collects one record per profiled task (see the module docstring).

    Args:
        n_images: Val scenes per task (the profile's ``n_val``): images/s of the stages that process them.
        device: The run's device; on CUDA the task records torch's peak allocated memory too.
        trace_python: Also record the peak of Python / NumPy allocations (tracemalloc; slow).
    """

    def __init__(self, n_images: int, device: str = "cpu", trace_python: bool = False) -> None:
        self.n_images = n_images
        self.device = device
        self.trace_python = trace_python
        self.tasks: list[dict[str, Any]] = []
        self.started = time.perf_counter()

    @contextlib.contextmanager
    def task(self, task: Task) -> Iterator[None]:
        """Profile the body of one task (``benchmark.runner.planning.Task``)."""
        cuda = self.device.startswith("cuda") and torch.cuda.is_available()
        if cuda:
            torch.cuda.reset_peak_memory_stats()
        traced_here = self.trace_python and not tracemalloc.is_tracing()
        if traced_here:
            tracemalloc.start()
        if self.trace_python:
            tracemalloc.reset_peak()
        rss_before = _maxrss_mib()
        profile = cProfile.Profile()
        sampler = PeakSampler({s.name: s.functions for s in STAGES})
        t0 = time.perf_counter()
        profile.enable()
        try:
            with sampler:
                yield
        finally:
            if cuda:
                torch.cuda.synchronize()  # the task's queued kernels belong to its seconds
            profile.disable()
            seconds = time.perf_counter() - t0
            python_peak_mib = tracemalloc.get_traced_memory()[1] / 2**20 if self.trace_python else None
            if traced_here:
                tracemalloc.stop()
            record: dict[str, Any] = {
                "key": task.key, "kind": task.kind, "label": _label(task), "lens": task.lens, "seed": task.seed,
                "seconds": seconds,
                "rss_peak_mib": _maxrss_mib(), "rss_growth_mib": _maxrss_mib() - rss_before,
                "python_peak_mib": python_peak_mib,
                **({"torch_cuda_peak_mib": torch.cuda.max_memory_allocated() / 2**20} if cuda else {}),
                "rss_sampled": sampler.summary(),
            }
            stats = pstats.Stats(profile)
            record["stages"] = _stages(stats, seconds, self.n_images, sampler.group_peaks_mib)
            record["top_functions"] = _top_functions(stats, seconds)
            # A task that pushes the val scenes through a stage processes n_images scenes end to end.
            scenes = any(s["images"] for s in record["stages"])
            record["images_per_s"] = self.n_images / seconds if scenes and seconds > 0 else None
            self.tasks.append(record)

    def summary(self) -> dict[str, Any]:
        """The profile: every task record, shares of the profiled time, and the machine's state."""
        total = sum(t["seconds"] for t in self.tasks)
        for t in self.tasks:
            t["share"] = t["seconds"] / total if total else 0.0
        return {"profiled_s": total, "wall_s": time.perf_counter() - self.started, "n_images_per_task": self.n_images,
                "threads": torch.get_num_threads(), "cpus": os.cpu_count(), "load_average": list(os.getloadavg()),
                "rss_peak_mib": _maxrss_mib(), "device": self.device, "tasks": self.tasks}


def _where(func: tuple[str, int, str]) -> str:
    filename, line, name = func
    parts = Path(filename).parts
    short = "/".join(parts[-2:]) if len(parts) >= 2 else filename
    return f"{short}:{line}({name})"


def _stages(stats: pstats.Stats, seconds: float, n_images: int,
            peaks_mib: dict[str, float] | None = None) -> list[dict[str, Any]]:
    table = stats.stats  # type: ignore[attr-defined]  # {(file, line, name): (cc, nc, tt, ct, callers)}
    out = []
    for stage in STAGES:
        cum, calls = 0.0, 0
        for (filename, _, name), (_, nc, _, ct, _) in table.items():
            if any(name == fn and filename.replace(os.sep, "/").endswith(suffix) for suffix, fn in stage.functions):
                cum += ct
                calls += nc
        if calls:
            images = calls * n_images if stage.per_call_images else 0
            out.append({"stage": stage.name, "seconds": cum, "share": cum / seconds if seconds > 0 else 0.0,
                        "calls": calls, "images": images, "images_per_s": images / cum if images and cum > 0 else None,
                        "rss_peak_mib": (peaks_mib or {}).get(stage.name)})
    return out


def _top_functions(stats: pstats.Stats, seconds: float, n: int = TOP_FUNCTIONS) -> list[dict[str, Any]]:
    """The ``n`` functions with the most cumulative time, skipping the profiler's own frames, contextlib,
    and the task body with anything else holding all of the task's time (>= 99 %: it says nothing)."""
    table = stats.stats  # type: ignore[attr-defined]
    rows = sorted(table.items(), key=lambda kv: -kv[1][3])
    out = []
    for func, (_, nc, tt, ct, _) in rows:
        if func[0] in ("~", "<string>") or "contextlib" in func[0] or "profiling.py" in func[0] or ct >= 0.99 * seconds:
            continue
        out.append({"function": _where(func), "calls": nc, "cumulative_s": ct, "own_s": tt,
                    "share": ct / seconds if seconds > 0 else 0.0})
        if len(out) == n:
            break
    return out


@contextlib.contextmanager
def task_scope(task: Task) -> Iterator[None]:
    """Profile a task body when a run profiler is active (``profiled``); otherwise do nothing."""
    if _ACTIVE is None:
        yield
        return
    with _ACTIVE.task(task):
        yield


def _label(task: Task) -> str:
    """What the cost table calls a task: its kind, and for a fit the restorer it fits."""
    return f"fit {task.restorers[0].name}" if task.kind == "fit" and task.restorers else task.kind


@contextlib.contextmanager
def profiled(out: Path, n_images: int, device: str = "cpu", executor: str = "local",
             trace_python: bool = False) -> Iterator[RunProfiler]:
    """Profile every task computed inside the block; then write ``out``/profile.json and profile.md.

    Raises:
        ValueError: ``executor`` is not "local" (Ray runs tasks in other processes, out of reach).
    """
    global _ACTIVE
    if executor != "local":
        raise ValueError(f"--profile-time profiles tasks in this process; use --executor local, not {executor!r}")
    if _ACTIVE is not None:
        raise RuntimeError("a run profiler is already active in this process")
    _ACTIVE = RunProfiler(n_images, device, trace_python)
    try:
        yield _ACTIVE
    finally:
        profiler, _ACTIVE = _ACTIVE, None
        summary = profiler.summary()
        out.mkdir(parents=True, exist_ok=True)
        (out / "profile.json").write_text(json.dumps(summary, indent=1, sort_keys=True) + "\n")
        (out / "profile.md").write_text(render_markdown(summary))


def _fmt(value: float | None, spec: str) -> str:
    return "" if value is None else format(value, spec)


def cost_table(profile: dict[str, Any]) -> str:
    """The README's cost table: one line per task kind (and lens), seconds, share, images/s, peak memory."""
    groups: dict[tuple[str, str], list[dict[str, Any]]] = {}
    for t in profile["tasks"]:
        groups.setdefault((t["label"], t["lens"] or "-"), []).append(t)
    total = profile["profiled_s"] or 1.0
    lines = ["| task | lens | tasks | seconds | share | images/s | peak RSS MiB |", "|---|---|---:|---:|---:|---:|---:|"]
    for (kind, lens), tasks in sorted(groups.items(), key=lambda kv: -sum(t["seconds"] for t in kv[1])):
        seconds = sum(t["seconds"] for t in tasks)
        rates = [t["images_per_s"] for t in tasks if t.get("images_per_s")]
        lines.append(f"| {kind} | {lens} | {len(tasks)} | {seconds:.1f} | {seconds / total:.1%} | "
                     f"{_fmt(sum(rates) / len(rates) if rates else None, '.2f')} | "
                     f"{max(t['rss_peak_mib'] for t in tasks):.0f} |")
    load = ", ".join(f"{x:.1f}" for x in profile.get("load_average", []))
    lines.append(f"\nProfiled {profile['profiled_s']:.1f} s of tasks ({profile['wall_s']:.1f} s wall), "
                 f"{profile['threads']} torch threads on {profile['cpus']} CPUs, load average {load} at the end; "
                 f"peak RSS {profile['rss_peak_mib']:.0f} MiB.")
    return "\n".join(lines) + "\n"


def stage_table(profile: dict[str, Any]) -> str:
    """Per pipeline stage, summed over the tasks: seconds, share of the profiled time, images/s."""
    sums: dict[str, dict[str, float]] = {}
    for t in profile["tasks"]:
        for s in t["stages"]:
            acc = sums.setdefault(s["stage"], {"seconds": 0.0, "images": 0.0, "calls": 0.0})
            acc["seconds"] += s["seconds"]
            acc["images"] += s["images"]
            acc["calls"] += s["calls"]
    total = profile["profiled_s"] or 1.0
    lines = ["| stage | calls | seconds | share of run | images/s |", "|---|---:|---:|---:|---:|"]
    order = [s.name for s in STAGES]
    for name in sorted(sums, key=order.index):
        acc = sums[name]
        rate = acc["images"] / acc["seconds"] if acc["images"] and acc["seconds"] > 0 else None
        lines.append(f"| {name} | {acc['calls']:.0f} | {acc['seconds']:.1f} | {acc['seconds'] / total:.1%} | "
                     f"{_fmt(rate, '.2f')} |")
    return "\n".join(lines) + "\n\nStages nest (reading includes segmentation), so shares need not add up to 100 %.\n"


ASYNC_NOTE = ("On a GPU, kernels run asynchronously: a stage's seconds (and images/s) count the time the host "
              "spends in it, and a kernel's time falls in the stage that waits for its result (a copy to the CPU, "
              "say). Task seconds are exact: each task waits for its kernels before it is timed.\n")


def render_markdown(profile: dict[str, Any]) -> str:
    """profile.md: the cost table, the stage table, then per task its stages and top functions."""
    parts = ["# Where the time went\n", "## Tasks\n", cost_table(profile), "## Stages\n", stage_table(profile)]
    if str(profile.get("device", "cpu")).startswith("cuda"):
        parts.append(ASYNC_NOTE)
    for t in sorted(profile["tasks"], key=lambda t: -t["seconds"]):
        parts.append(f"## {t['key']} ({t['seconds']:.1f} s, {t['share']:.1%})\n")
        python = (f"Python/NumPy peak {t['python_peak_mib']:.0f} MiB" if t.get("python_peak_mib") is not None
                  else "Python/NumPy allocations not traced (--profile-python-memory)")
        parts.append(f"Peak RSS {t['rss_peak_mib']:.0f} MiB (+{t['rss_growth_mib']:.0f} in this task), {python}"
                     + (f", torch CUDA peak {t['torch_cuda_peak_mib']:.0f} MiB" if "torch_cuda_peak_mib" in t else "")
                     + (f", {t['images_per_s']:.2f} images/s" if t.get("images_per_s") else "") + ".\n")
        sampled = t.get("rss_sampled") or {}
        if sampled.get("peak_mib") is not None:
            parts.append(f"Sampled resident peak {sampled['peak_mib']:.0f} MiB (from {sampled['start_mib']:.0f} at the "
                         f"start; {sampled['samples']} samples, every {sampled['interval_s'] * 1000:.0f} ms), set in:\n\n"
                         + "".join(f"    {frame}\n" for frame in sampled["peak_stack"]) + "\n")
        if t["stages"]:
            parts.append("| stage | calls | seconds | share | images/s | sampled peak RSS MiB |\n"
                         "|---|---:|---:|---:|---:|---:|\n" + "".join(
                f"| {s['stage']} | {s['calls']} | {s['seconds']:.2f} | {s['share']:.1%} | "
                f"{_fmt(s['images_per_s'], '.2f')} | {_fmt(s.get('rss_peak_mib'), '.0f')} |\n" for s in t["stages"]))
        parts.append("\n| function (cumulative) | calls | cumulative s | own s | share |\n|---|---:|---:|---:|---:|\n"
                     + "".join(f"| `{f['function']}` | {f['calls']} | {f['cumulative_s']:.2f} | {f['own_s']:.2f} | "
                               f"{f['share']:.1%} |\n" for f in t["top_functions"]))
    return "\n".join(parts)


def main(argv: list[str] | None = None) -> int:
    """``python -m benchmark.runner.diagnostics.profiling RUN/profile.json``: print its cost and stage tables (for the README)."""
    args = sys.argv[1:] if argv is None else argv
    if len(args) != 1 or not Path(args[0]).is_file():
        print("usage: python -m benchmark.runner.diagnostics.profiling RUN_FOLDER/profile.json (written by run --profile-time)",
              file=sys.stderr)
        return 2
    profile = json.loads(Path(args[0]).read_text())
    print(cost_table(profile) + "\n" + stage_table(profile), end="")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
