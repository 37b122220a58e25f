"""Which code holds the memory when a task peaks: resident memory sampled with the profiled thread's stack.

``getrusage`` gives a process's high-water mark but not who set it; tracemalloc sees Python and NumPy
allocations but not torch's. ``PeakSampler`` polls the process's *current* resident memory
(``/proc/self/statm``) from a background thread every ``interval`` seconds and, with each sample, the
stack of the thread being profiled. It keeps the stack of the highest sample (where the peak was set)
and, per named group of functions (the profiler's pipeline stages), the highest sample taken while one
of them was on the stack. Torch kernels release the GIL, so samples land during them too; a peak that
lives shorter than ``interval`` can be missed (the ``getrusage`` mark still catches it), so the sampled
peak is a lower bound on the true one. The kernel's resident count lags by milliseconds (it is
synchronised in batches), so a sample may land on the code that runs just after a block is freed.

Linux only (``/proc``); elsewhere ``available()`` is False and the sampler records nothing.
"""

from __future__ import annotations

import os
import sys
import threading
from collections.abc import Mapping, Sequence
from pathlib import Path
from types import FrameType
from typing import Any

__all__ = ["PeakSampler", "available", "current_rss_mib"]

_STATM = Path("/proc/self/statm")
_PAGE_MIB = os.sysconf("SC_PAGE_SIZE") / 2**20 if hasattr(os, "sysconf") else 0.0
# Frames of these files are the interesting ones in a peak stack (the rest is the interpreter's plumbing).
OWN_PACKAGES = ("benchmark", "attacks", "lenses")
DRIFT_MIB = 16.0


def available() -> bool:
    return _STATM.is_file() and _PAGE_MIB > 0


def current_rss_mib() -> float | None:
    """The process's resident memory now, MiB (None where /proc is missing)."""
    try:
        return int(_STATM.read_text().split()[1]) * _PAGE_MIB
    except (OSError, IndexError, ValueError):
        return None


def _stack(frame: FrameType | None) -> list[tuple[str, int, str]]:
    """(file, line, function) from the outermost frame to `frame`."""
    out = []
    while frame is not None:
        out.append((frame.f_code.co_filename.replace(os.sep, "/"), frame.f_lineno, frame.f_code.co_name))
        frame = frame.f_back
    return out[::-1]


def _common_prefix(a: list[tuple[str, int, str]], b: list[tuple[str, int, str]]) -> list[tuple[str, int, str]]:
    """The frames of `a` that `b` still has at the same depth (same file and function)."""
    n = 0
    while n < min(len(a), len(b)) and (a[n][0], a[n][2]) == (b[n][0], b[n][2]):
        n += 1
    return a[:n]


def _short(filename: str) -> str:
    parts = filename.split("/")
    for i in range(len(parts) - 1, -1, -1):
        if parts[i] in OWN_PACKAGES:
            return "/".join(parts[i:])
    return "/".join(parts[-2:])


class PeakSampler:
    """Sample resident memory and the profiled thread's stack while the ``with`` block runs.

    Args:
        groups: name -> (file path suffix, function name) pairs; ``group_peaks_mib`` holds, per name,
            the highest sample taken while one of its functions was on the stack.
        interval: Seconds between samples.
        thread_id: The thread whose stack is sampled (default: the one that enters the block).
    """

    def __init__(self, groups: Mapping[str, Sequence[tuple[str, str]]] | None = None, interval: float = 0.02,
                 thread_id: int | None = None) -> None:
        self.groups = dict(groups or {})
        self.interval = interval
        self.thread_id = thread_id
        self.samples = 0
        self.start_mib: float | None = None
        self.peak_mib: float | None = None
        self.peak_stack: list[tuple[str, int, str]] = []
        self._stack_mib: float | None = None  # the sample the peak's stack was taken at
        self.group_peaks_mib: dict[str, float] = {}
        self._stop = threading.Event()
        self._thread: threading.Thread | None = None

    def __enter__(self) -> PeakSampler:
        if not available():
            return self
        if self.thread_id is None:
            self.thread_id = threading.get_ident()
        self.start_mib = current_rss_mib()
        self._thread = threading.Thread(target=self._run, name="peak-sampler", daemon=True)
        self._thread.start()
        return self

    def __exit__(self, *exc: object) -> None:
        if self._thread is not None:
            self._stop.set()
            self._thread.join()
            self._sample()  # the state at the end counts too

    def _run(self) -> None:
        while not self._stop.wait(self.interval):
            self._sample()

    def _sample(self) -> None:
        # Reading /proc releases the GIL, so the profiled thread may move on meanwhile: a sample is
        # attributed only to the frames on its stack both before and after the reading.
        before = self._stack()
        rss = current_rss_mib()
        if rss is None:
            return
        stack = _common_prefix(before, self._stack())
        self.samples += 1
        # A new peak moves the peak's stack only once it is DRIFT_MIB above the sample the stack was
        # taken at: allocator drift later on must not take the stack away from the code that set the
        # peak (at 1 MiB, a clean-clone CI run saw the injected 256 MiB peak's stack move to the
        # function that ran after the block was freed). Measured from the stack's own sample, not from
        # the running peak, so that a block paged in a few MiB per sample still moves it.
        if self.peak_mib is None or rss > self.peak_mib:
            self.peak_mib = rss
            if self._stack_mib is None or rss > self._stack_mib + DRIFT_MIB:
                self.peak_stack, self._stack_mib = stack, rss
        on_stack = {(f, name) for f, _, name in stack}
        for group, functions in self.groups.items():
            if any(name == fn and f.endswith(suffix) for f, name in on_stack for suffix, fn in functions):
                if rss > self.group_peaks_mib.get(group, -1.0):
                    self.group_peaks_mib[group] = rss

    def _stack(self) -> list[tuple[str, int, str]]:
        if self.thread_id is None:
            return []
        # The dict of frames must not be bound to a local: it holds this very frame, whose locals would
        # then hold the dict, a cycle that keeps every sampled frame, and so the locals of functions that
        # have returned meanwhile (a task's big arrays), alive until the next garbage collection.
        frame = sys._current_frames().get(self.thread_id)  # noqa: SLF001  # the documented way to see another thread's stack
        return _stack(frame)

    def summary(self, frames: int = 12) -> dict[str, Any]:
        """The sampled peak, the start, the deepest `frames` of our own frames at the peak, and the group peaks."""
        own = [f for f in self.peak_stack if _short(f[0]).split("/")[0] in OWN_PACKAGES]
        return {"samples": self.samples, "interval_s": self.interval, "start_mib": self.start_mib,
                "peak_mib": self.peak_mib,
                "peak_stack": [f"{_short(f)}:{line}({name})" for f, line, name in own[-frames:]],
                "group_peaks_mib": dict(self.group_peaks_mib)}
