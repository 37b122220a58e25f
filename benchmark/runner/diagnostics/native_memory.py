"""Bounds on memory that torch's native CPU libraries keep outside Python's sight.

oneDNN, which runs torch's CPU convolutions, caches every primitive it compiles (one per layer,
input shape and direction) with the buffers it owns, up to ``ONEDNN_PRIMITIVE_CACHE_CAPACITY``
primitives, 1024 by default. The evaluation feeds networks hundreds of plate windows of distinct
sizes, so the cache only grows: with torch 2.14.1 by gigabytes in a quick evaluation, enough to have
a quick run killed for memory (docs/costs.md; docs/history.md). At 128 the cache still holds most of a
training step's primitives: a step is a few per cent slower than at 1024, and at 64 slower still
(docs/history.md).

The capacity is read when oneDNN first builds a primitive, so it is set when ``benchmark`` is
imported, before any network runs; a value the user set in the environment is kept.

glibc's allocator keeps what a task frees for later allocations instead of giving it back to the
system: torch's large tensors land in its heap once the mmap threshold has risen (it follows the
largest block freed, up to 32 MB), so the process's resident size only ever grows, task after task.
``release_free_memory`` hands the free heap back (``malloc_trim``), which brings a process that has
trained and run networks and deleted them back to near its starting size (docs/history.md). The runner
calls it after each task, the evaluation after each stage of a restorer (its restore, its PSNR/SSIM,
each read chain): trimmed only between restorers, a quick run held gigabytes of freed heap at the end
of each restorer's step (docs/costs.md, traced with ``mallinfo2``).
A fixed mmap threshold (``M_MMAP_THRESHOLD`` 4 MiB, so that freed tensors unmap at once) was the
other way; it made a quick NAFNet's inference and, far more, its training steps slower (page faults
on every large tensor; docs/history.md), so it is not used.
"""

from __future__ import annotations

import ctypes
import ctypes.util
import functools
import gc
import os

ONEDNN_CACHE_VARIABLE = "ONEDNN_PRIMITIVE_CACHE_CAPACITY"
ONEDNN_CACHE_CAPACITY = 128


def bound_onednn_cache() -> str:
    """Set oneDNN's primitive cache capacity unless the environment already names one; return the value in force."""
    return os.environ.setdefault(ONEDNN_CACHE_VARIABLE, str(ONEDNN_CACHE_CAPACITY))


@functools.cache
def _libc() -> ctypes.CDLL | None:
    """glibc, when this process runs on it (``malloc_trim`` is a glibc extension), else None."""
    name = ctypes.util.find_library("c")
    try:
        libc = ctypes.CDLL(name) if name else None
    except OSError:
        return None
    return libc if libc is not None and hasattr(libc, "malloc_trim") else None


class _MallInfo2(ctypes.Structure):
    _fields_ = [(name, ctypes.c_size_t) for name in ("arena", "ordblks", "smblks", "hblks", "hblkhd", "usmblks",
                                                      "fsmblks", "uordblks", "fordblks", "keepcost")]


def live_heap_bytes() -> int | None:
    """Bytes malloc has handed out and not had back (heap chunks in use plus mmapped blocks, glibc's
    ``mallinfo2``): what the process keeps alive, without the free heap the resident size also holds;
    None off glibc or before glibc 2.33."""
    libc = _libc()
    if libc is None or not hasattr(libc, "mallinfo2"):
        return None
    libc.mallinfo2.restype = _MallInfo2
    info = libc.mallinfo2()
    return int(info.uordblks + info.hblkhd)


def release_free_memory() -> bool:
    """Collect Python's garbage, then give the allocator's free heap back to the system; returns
    whether it could (False off glibc, where only the collection runs)."""
    gc.collect()
    libc = _libc()
    if libc is None:
        return False
    libc.malloc_trim(0)
    return True
