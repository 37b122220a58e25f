"""The CLI end to end on the smoke profile: files, row schema and the physics it must show."""

import subprocess
import sys

import pytest

from benchmark.schema import read_results

PROVENANCE = {"git_commit", "packages", "device", "threads", "wall_s", "date"}


@pytest.fixture(scope="module")
def smoke_run(tmp_path_factory):
    out = tmp_path_factory.mktemp("run")
    # The cheap attackers: each registered attacker has its own tests.
    proc = subprocess.run([sys.executable, "-m", "benchmark", "run", "--lens", "ideal", "--lens", "defocus",
                           "--attack", "identity", "--attack", "wiener-known-psf", "--attack", "lpdr-oracle",
                           "--profile", "smoke", "--out", str(out)], capture_output=True, text=True, timeout=600)
    assert proc.returncode == 0, proc.stderr[-3000:]
    return out, proc


def test_run_writes_results_tables_and_pictures(smoke_run):
    out, proc = smoke_run
    for name in ("results.json", "table.md", "table.csv", "samples_ideal_seed0.png", "samples_defocus_seed0.png"):
        assert (out / name).stat().st_size > 0, name
    assert "| lens" in proc.stdout


def test_rows_follow_the_schema(smoke_run):
    out, _ = smoke_run
    results = read_results(out / "results.json")  # validates every row against the schema
    assert results.meta["profile"]["name"] == "smoke"
    rows = results.rows
    assert {(r.lens, r.attack) for r in rows} >= {
        (lens, a) for lens in ("ideal", "defocus")
        for a in ("lens", "utility", "bound", "identity", "wiener-known-psf", "lpdr-oracle",
                  "identity>lpdr-oracle", "wiener-known-psf>lpdr-oracle")} | {("sharp", "utility"), ("sharp", "lpdr-oracle")}
    for r in rows:
        assert PROVENANCE <= set(r.provenance), PROVENANCE - set(r.provenance)
        assert r.profile == "smoke" and r.scenes == "synthetic" and r.seed == 0 and r.ok
        m = r.metrics
        if "psnr_db" in m:
            assert r.kind == "restorer"
            assert 0 < m["ssim"] <= 1 and m["psnr_db"] > 0 and m["fit_s"] >= 0 and m["images_per_s"] > 0
        if "plate_acc" in m:
            assert r.kind in ("reader", "chain") and 0 <= m["plate_acc"] <= 1 and m["n_plates"] >= 0
        if r.kind == "utility":
            assert 0 <= m["miou"] <= m["mean_acc"] + 1e-9 and 0 <= m["overall_acc"] <= 1  # IoU <= recall per class


def test_ideal_keeps_psnr_defocus_drops_it_and_wiener_beats_identity(smoke_run):
    out, _ = smoke_run
    rows = {(r.lens, r.attack): r.metrics for r in read_results(out / "results.json").rows}
    best_ideal = max(rows["ideal", a]["psnr_db"] for a in ("identity", "wiener-known-psf"))
    best_defocus = max(rows["defocus", a]["psnr_db"] for a in ("identity", "wiener-known-psf"))
    assert best_ideal > best_defocus + 3
    assert rows["defocus", "wiener-known-psf"]["psnr_db"] > rows["defocus", "identity"]["psnr_db"] + 1


def test_unknown_lens_fails_fast_with_suggestion(tmp_path):
    proc = subprocess.run([sys.executable, "-m", "benchmark", "run", "--lens", "idael", "--profile", "smoke",
                           "--out", str(tmp_path)], capture_output=True, text=True, timeout=120)
    assert proc.returncode == 2
    assert "unknown lens 'idael'" in proc.stderr and "ideal" in proc.stderr


def test_list_shows_lenses_attackers_and_scene_sets():
    proc = subprocess.run([sys.executable, "-m", "benchmark", "list"], capture_output=True, text=True, timeout=120)
    assert proc.returncode == 0
    for name in ("ideal", "defocus", "random-zernike", "identity", "wiener-known-psf", "synthetic", "photos"):
        assert name in proc.stdout
