"""The CLI end to end on the smoke profile: files, row schema and the physics it must show."""

import subprocess
import sys

import pytest

from benchmark.results.schema import read_results

pytestmark = pytest.mark.slow  # runs `python -m benchmark` in subprocesses

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


def test_final_line_names_every_file_written(smoke_run):
    """The run's "wrote" line lists every file in --out: charts, plates.csv, ceiling_check.json included."""
    out, proc = smoke_run
    line = next(x for x in proc.stdout.splitlines()[::-1] if x.startswith("wrote "))
    assert line.startswith(f"wrote {out}/: ")
    named = set(line[len(f"wrote {out}/: "):].rsplit(" (", 1)[0].split(", "))
    on_disk = {str(p.relative_to(out)) for p in out.rglob("*") if p.is_file()}
    assert named == on_disk and {"results.json", "table.md", "table.csv"} <= named
    assert any(name.endswith(".png") and not name.startswith("samples_") for name in named)  # a chart


def test_plate_readers_on_scenes_without_plates_say_so(tmp_path):
    """--scenes photos has no plates: the reader's row fails with that sentence (was a ZeroDivisionError),
    and the other rows are written."""
    proc = subprocess.run([sys.executable, "-m", "benchmark", "-q", "run", "--lens", "ideal", "--scenes", "photos",
                           "--attack", "identity", "--attack", "lpdr-oracle", "--profile", "smoke", "--out",
                           str(tmp_path)], capture_output=True, text=True, timeout=600)
    assert proc.returncode == 1, proc.stderr[-3000:]
    assert "ZeroDivisionError" not in proc.stderr + proc.stdout
    results = read_results(tmp_path / "results.json")
    failed = [r for r in results.rows if not r.ok]
    assert failed and {r.reader for r in failed} == {"lpdr-oracle"}
    for r in failed:
        assert "the scenes 'photos' hold no licence plates" in r.error.message
    assert any(r.ok and r.kind == "restorer" and r.attack == "identity" for r in results.rows)


def test_rows_follow_the_schema(smoke_run):
    out, _ = smoke_run
    results = read_results(out / "results.json")
    assert results.meta["profile"]["name"] == "smoke"
    rows = results.rows
    assert {(r.kind, r.lens, r.attack) for r in rows} >= {
        (kind, lens, a) for lens in ("ideal", "defocus")
        for kind, a in (("lens", "lens"), ("utility", "utility"), ("bound", "bound"), ("restorer", "identity"),
                        ("restorer", "wiener-known-psf"), ("reader", "lpdr-oracle"), ("chain", "identity>lpdr-oracle"),
                        ("chain", "wiener-known-psf>lpdr-oracle"))} | {("utility", "sharp", "utility"),
                                                                       ("reader", "sharp", "lpdr-oracle")}
    for r in rows:
        assert r.ok and PROVENANCE <= set(r.provenance), PROVENANCE - set(r.provenance)
        assert r.profile == "smoke" and r.scenes == "synthetic" and r.seed == 0
        settings = results.settings[r.settings_hash]  # every number leads back to its settings
        if r.kind == "restorer":
            assert settings["restorer"]["name"] == r.restorer and settings["lens"]["name"] == r.lens
            assert 0 < r.metrics["ssim"] <= 1 and r.metrics["psnr_db"] > 0 and r.metrics["images_per_s"] > 0
            low, high = r.interval("psnr_db")
            assert r.interval_methods["psnr_db"] == "bootstrap" and low <= r.metrics["psnr_db"] <= high
        if r.kind in ("reader", "chain"):
            assert settings["reader"]["name"] == r.reader
            assert 0 <= r.metrics["plate_acc"] <= 1 and r.metrics["n_plates"] >= 0
            low, high = r.interval("plate_acc")
            assert r.interval_methods["plate_acc"] == "wilson" and 0 <= low <= r.metrics["plate_acc"] <= high <= 1
        if r.kind == "reader":  # its own row carries its fit's seconds (what a lens costs); its chains do not
            assert r.metrics["fit_s"] >= 0
        if r.kind == "chain":
            assert settings["restorer"]["name"] == r.restorer and "fit_s" not in r.metrics
        if r.kind == "utility":
            m = r.metrics
            assert 0 <= m["miou"] <= m["mean_acc"] + 1e-9 and 0 <= m["overall_acc"] <= 1  # IoU <= recall per class


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


@pytest.mark.parametrize("flags, named", [
    (["--profile-python-memory"], "--profile-time"),
    (["--dry-run", "--profile-time"], "--profile-time"),
    (["--dry-run", "--publish"], "--publish"),
])
def test_run_flags_that_cannot_go_together_are_refused_before_any_work(flags, named, tmp_path, capsys):
    from benchmark.cli import main
    with pytest.raises(SystemExit) as stop:
        main(["run", "--lens", "ideal", "--profile", "smoke", "--out", str(tmp_path / "out"), *flags])
    assert stop.value.code == 2
    err = capsys.readouterr().err
    assert named in err and "usage:" in err
    assert not (tmp_path / "out").exists()
