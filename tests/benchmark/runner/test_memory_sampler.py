"""The peak sampler (benchmark/runner/diagnostics/memory_sampler.py) names the code that holds the memory at a task's peak.

An injected fault: a function that allocates and touches 256 MiB and holds it; the sampled peak must
rise by about that much, its stack must end in that function, and only the group naming it gets the peak.
"""

from __future__ import annotations

import gc
import mmap
import time
import weakref

import numpy as np
import pytest

from benchmark.runner.diagnostics import memory_sampler
from benchmark.runner.diagnostics.memory_sampler import PeakSampler

pytestmark = pytest.mark.skipif(not memory_sampler.available(), reason="needs /proc/self/statm (Linux)")

HOG_MIB = 256


def hold_a_big_array() -> float:
    block = np.ones(HOG_MIB * 2**20 // 8)  # float64, every page written
    time.sleep(0.3)  # held for many sampling intervals
    return float(block[-1])


def small_work() -> None:
    time.sleep(0.1)


def after_work() -> None:
    time.sleep(0.1)


def test_the_peak_and_its_stack_point_at_the_allocating_function():
    groups = {"hog": [("tests/benchmark/runner/test_memory_sampler.py", "hold_a_big_array")],
              "small": [("tests/benchmark/runner/test_memory_sampler.py", "small_work")],
              "absent": [("benchmark/nowhere.py", "never_called")]}
    with PeakSampler(groups, interval=0.01) as sampler:
        small_work()
        hold_a_big_array()
        after_work()
    summary = sampler.summary()
    assert summary["samples"] >= 20
    rise = summary["peak_mib"] - summary["start_mib"]
    assert 0.8 * HOG_MIB <= rise <= 1.5 * HOG_MIB
    assert sampler.peak_stack[-1][2] == "hold_a_big_array" or sampler.peak_stack[-2][2] == "hold_a_big_array"
    assert summary["group_peaks_mib"]["hog"] >= summary["peak_mib"] - memory_sampler.DRIFT_MIB
    # The small function ran before the big array lived: its peak stays well below. (Not asserted for
    # after_work: the kernel's resident count can lag a freed block by a few milliseconds.)
    assert summary["group_peaks_mib"]["small"] < summary["peak_mib"] - 0.5 * HOG_MIB
    assert "absent" not in summary["group_peaks_mib"]


RAMP_MIB, RAMP_STEP_MIB = 128, 4


def page_in_slowly() -> None:
    """A fresh anonymous block paged in a few MiB at a time: no sample beats the last by DRIFT_MIB."""
    block = mmap.mmap(-1, RAMP_MIB * 2**20)
    view = np.frombuffer(block, dtype=np.uint8)
    step = RAMP_STEP_MIB * 2**20
    for start in range(0, view.size, step):
        view[start:start + step:4096] = 1  # one write per page
        time.sleep(0.01)
    time.sleep(0.1)
    del view
    block.close()


def test_a_peak_paged_in_slowly_still_takes_the_stack():
    """A CI run at DRIFT_MIB = 16 measured from the running peak: the 256 MiB block paged in about
    6 MiB per sample, so the stack stayed on the function before it."""
    assert RAMP_STEP_MIB < memory_sampler.DRIFT_MIB
    with PeakSampler({}, interval=0.01) as sampler:
        small_work()
        page_in_slowly()
        after_work()
    assert sampler.peak_mib - sampler.start_mib >= 0.8 * RAMP_MIB
    assert "page_in_slowly" in [name for _, _, name in sampler.peak_stack[-2:]]


def test_sampling_does_not_keep_a_returned_function_s_locals_alive():
    """Sampling a stack must not keep its frames, and so their arrays, alive past their function's
    return: the sampler's dict of frames once made a reference cycle that held them until the next
    garbage collection (the 256 MiB block was still resident when the next test started)."""
    def hold(refs: list) -> None:
        block = np.ones(1024)
        refs.append(weakref.ref(block))
        time.sleep(0.2)  # sampled many times while alive

    refs: list = []
    gc.disable()  # only reference counting may free the block
    try:
        with PeakSampler({}, interval=0.005) as sampler:
            hold(refs)
            # The sampler may be halfway through a walk of the stack when `hold` returns; it lets go
            # of the frame within microseconds. Without gc, a cycle would hold the block for good.
            deadline = time.monotonic() + 1.0
            while refs[0]() is not None and time.monotonic() < deadline:
                time.sleep(0.01)
            freed = refs[0]() is None
    finally:
        gc.enable()
    assert freed
    assert sampler.samples >= 10


def test_current_rss_tracks_an_allocation():
    before = memory_sampler.current_rss_mib()
    block = np.ones(HOG_MIB * 2**20 // 8)
    during = memory_sampler.current_rss_mib()
    del block
    assert during - before >= 0.8 * HOG_MIB
