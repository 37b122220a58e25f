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
"""

from __future__ import annotations

import os

ONEDNN_CACHE_VARIABLE = "ONEDNN_PRIMITIVE_CACHE_CAPACITY"
ONEDNN_CACHE_CAPACITY = 128


def bound_onednn_cache() -> str:
    """Set oneDNN's primitive cache capacity unless the environment already names one; return the value in force."""
    return os.environ.setdefault(ONEDNN_CACHE_VARIABLE, str(ONEDNN_CACHE_CAPACITY))
