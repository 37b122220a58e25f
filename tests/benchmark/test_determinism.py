"""Same seed on the same machine gives identical numbers (training included)."""

import json
import subprocess
import sys

# Timing, and provenance that names when and at which commit rather than what was measured.
TIMING = {"fit_s", "images_per_s", "wall_s", "date", "git_commit"}


def run(out, cache, env_extra=None):
    import os
    env = {**os.environ, "PLB_CACHE": str(cache)}
    proc = subprocess.run([sys.executable, "-m", "benchmark", "run", "--lens", "defocus", "--attack", "identity",
                           "--attack", "wiener-known-psf", "--profile", "smoke", "--seeds", "3", "--out", str(out)],
                          capture_output=True, text=True, timeout=600, env=env)
    assert proc.returncode == 0, proc.stderr[-2000:]
    return json.loads((out / "results.json").read_text())["rows"]


def test_same_seed_same_numbers_from_an_empty_cache(tmp_path):
    a = run(tmp_path / "a", tmp_path / "cache_a")
    b = run(tmp_path / "b", tmp_path / "cache_b")
    assert len(a) == len(b)
    for ra, rb in zip(a, b):
        for key in ra:
            if key in TIMING:
                continue
            assert ra[key] == rb[key], (ra["lens"], ra["attack"], key, ra[key], rb[key])
