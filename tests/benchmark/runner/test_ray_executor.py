"""The Ray executor gives the local executor's results, also when a worker dies mid-grid."""

import os
import subprocess
import sys
import textwrap

import pytest

from benchmark.results.schema import read_results

pytestmark = pytest.mark.slow  # smoke runs of `python -m benchmark` in subprocesses

pytest.importorskip("ray", reason='the Ray executor is an optional extra: pip install ".[ray]"')

# Timing, and provenance that names when and at which commit rather than what was measured.
TIMING = {"fit_s", "images_per_s", "wall_s", "date", "git_commit"}


def run(out, cache, executor, lenses=("ideal", "defocus"), seeds="0,1", extra=(), env_extra=None):
    env = {**os.environ, "PLB_CACHE": str(cache), **(env_extra or {})}
    args = [sys.executable, "-m", "benchmark", "run", "--profile", "smoke", "--seeds", seeds, "--out", str(out),
            "--executor", executor, "--attack", "identity", "--attack", "wiener-known-psf", *extra]
    for lens in lenses:
        args += ["--lens", lens]
    proc = subprocess.run(args, capture_output=True, text=True, timeout=900, env=env)
    assert proc.returncode == 0, proc.stderr[-3000:]
    return [r.flat() | {f"interval_{k}": v for k, v in r.intervals.items()}
            for r in read_results(out / "results.json").rows]


def same(a, b):
    assert [(r["lens"], r["attack"], r["seed"]) for r in a] == [(r["lens"], r["attack"], r["seed"]) for r in b]
    for ra, rb in zip(a, b):
        for key in set(ra) | set(rb):
            if key not in TIMING:
                assert ra.get(key) == rb.get(key), (ra["lens"], ra["attack"], key, ra.get(key), rb.get(key))


def test_ray_grid_matches_local(tmp_path):
    # One lens at two seeds: tasks of both seeds run at once on the workers (two lenses cost twice the time).
    local = run(tmp_path / "local", tmp_path / "cache-local", "local", lenses=("defocus",))
    on_ray = run(tmp_path / "ray", tmp_path / "cache-ray", "ray", lenses=("defocus",))
    same(local, on_ray)


def test_grid_survives_a_killed_worker(tmp_path):
    plugin = tmp_path / "crashy.py"
    plugin.write_text(textwrap.dedent('''
        import os
        from pathlib import Path
        from typing import ClassVar
        from attacks import Restorer, ThreatModel

        class Crashy(Restorer):
            """Kills its own worker process the first time it is fitted (a plugin that segfaults)."""
            name: ClassVar[str] = "crashy"
            threat_model: ClassVar[ThreatModel] = ThreatModel.SENSOR_ACCESS

            def fit(self, ctx):
                marker = os.environ.get("CRASHY_MARKER")
                if marker and not Path(marker).exists():
                    Path(marker).write_text("died once")
                    os._exit(1)

            def restore(self, sensor):
                return sensor.clamp(0, 1)
    '''))
    # In the worker's own process: isolated (the default), its exit would end only its attacker process.
    extra = ("--attack", f"{plugin}:Crashy", "--no-isolate")
    local = run(tmp_path / "local", tmp_path / "cache-local", "local", lenses=("defocus",), seeds="0", extra=extra)
    marker = tmp_path / "marker"
    on_ray = run(tmp_path / "ray", tmp_path / "cache-ray", "ray", lenses=("defocus",), seeds="0", extra=extra,
                 env_extra={"CRASHY_MARKER": str(marker)})
    assert marker.exists(), "the worker was never killed"
    same(local, on_ray)
    tasks = tmp_path / "cache-ray" / "tasks"
    leftovers = [p for p in tasks.rglob("*") if ".staging-" in p.name]
    assert not leftovers, leftovers
    assert all((d / "result.json").is_file() for run_dir in tasks.iterdir() for d in run_dir.iterdir() if d.is_dir())
