"""Bounds on memory that torch's native CPU libraries keep outside Python's sight.

oneDNN, which runs torch's CPU convolutions, caches every primitive it compiles (one per layer,
input shape and direction) with the buffers it owns, up to ``ONEDNN_PRIMITIVE_CACHE_CAPACITY``
primitives, 1024 by default. The evaluation feeds networks hundreds of plate windows of distinct
sizes, so the cache only grows: with torch 2.14.1 a quick NAFNet (width 16) on 60 windows of distinct
sizes grew the process by 2.0 GB at the default capacity and 2.1 GB at 256, by 0.6 GB at 64, and a
quick run of os-d-100 and os-info was killed for memory at 19.5 GB resident (2026-11-26; the same
runs peaked at 7-8 GB with torch 2.15.0). At 128 the cache still holds most of a training step's
primitives: a SegFormer-B0 + RED10 + NAFNet step at 128 x 128 took 1.07-1.09 s against 1.04 s at
1024 (fastest of 8, 1 thread, another job on the machine), 3-5 % slower; 64 was 5-7 % slower.

The capacity is read when oneDNN first builds a primitive, so it is set when ``benchmark`` is
imported, before any network runs; a value the user set in the environment is kept.

glibc's allocator keeps what a task frees for later allocations instead of giving it back to the
system: torch's large tensors land in its heap once the mmap threshold has risen (it follows the
largest block freed, up to 32 MB), so the process's resident size only ever grows, task after task.
``release_free_memory`` hands the free heap back (``malloc_trim``): after 8 quick NAFNet training
steps and restoring 17 frames and windows through ONNX Runtime, deleting everything left the process
at 1.72 GB and trimming brought it to 0.93 GB (from 0.84 GB at the start; 2026-11-27). The runner
calls it after each task, the evaluation after each stage of a restorer (its restore, its PSNR/SSIM,
each read chain): a fresh quick gp run, trimmed only between restorers, reached 8.1-8.4 GiB resident
at the end of each restorer's step while only 5.3-5.9 GB was in use (traced with ``mallinfo2``).
A fixed mmap threshold (``M_MMAP_THRESHOLD`` 4 MiB, so that freed tensors unmap at once) was the
other way; it made a quick NAFNet's inference 8 % and its training steps 50-75 % slower (page faults
on every large tensor), so it is not used.
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
