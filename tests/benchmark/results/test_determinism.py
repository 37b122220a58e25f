"""Same seed on the same machine gives identical numbers (training included)."""

import subprocess
import sys

import pytest

from benchmark.results.schema import read_results

pytestmark = pytest.mark.slow  # two smoke runs of `python -m benchmark` in subprocesses

# Timing, and provenance that names when and at which commit rather than what was measured.
TIMING = {"fit_s", "images_per_s", "wall_s", "date", "git_commit"}


def run(out, cache, env_extra=None):
    import os
    env = {**os.environ, "PLB_CACHE": str(cache)}
    proc = subprocess.run([sys.executable, "-m", "benchmark", "run", "--lens", "defocus", "--attack", "identity",
                           "--attack", "wiener-known-psf", "--profile", "smoke", "--seeds", "3", "--out", str(out)],
                          capture_output=True, text=True, timeout=600, env=env)
    assert proc.returncode == 0, proc.stderr[-2000:]
    return [r.to_json() for r in read_results(out / "results.json").rows]


def test_same_seed_same_numbers_from_an_empty_cache(tmp_path):
    a = run(tmp_path / "a", tmp_path / "cache_a")
    b = run(tmp_path / "b", tmp_path / "cache_b")
    assert len(a) == len(b)
    for ra, rb in zip(a, b):
        for part in ("kind", "lens", "attack", "metrics", "intervals", "settings_hash", "provenance"):
            va, vb = ra[part], rb[part]
            if isinstance(va, dict):
                va, vb = ({k: v for k, v in d.items() if k not in TIMING} for d in (va, vb))
            assert va == vb, (ra["lens"], ra["attack"], part, va, vb)
