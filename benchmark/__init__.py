"""Privacy Lens Bench runner: scenes, metrics, the run loop, reports, the CLI (`python -m benchmark`)
and the Python API::

    import benchmark
    results = benchmark.run(lenses=["ideal"], attacks=["wiener-known-psf"], profile="smoke")
    results.table()      # pandas DataFrame: one row per lens x attack x seed

The API (`benchmark.api`) is imported on first use, so `import benchmark` stays cheap.
"""

from __future__ import annotations

from typing import Any

from benchmark.runner.diagnostics.native_memory import bound_onednn_cache

bound_onednn_cache()  # before any network runs: see benchmark/runner/diagnostics/native_memory.py

_API = ("Plan", "PlannedTask", "Results", "list_attacks", "list_lenses", "list_scene_sets", "load_lens", "plan", "run")
__all__ = list(_API)


def __getattr__(name: str) -> Any:
    if name in _API:
        from benchmark import api
        return getattr(api, name)
    raise AttributeError(f"module 'benchmark' has no attribute {name!r}")


def __dir__() -> list[str]:
    return sorted(list(globals()) + list(_API))
