"""The PSF grid study: its records obey the physics they are meant to show, and its chart renders."""

import json

import pytest
import torch

from benchmark.publish import report as leaderboard_report
from benchmark.scenes.loading import load_scene
from benchmark.studies import psf_grid
from lenses.optics import choose_geometry


@pytest.fixture(scope="module")
def ideal_records():
    scene = load_scene("synthetic", "val", 0, (64, 128), 0)
    image = torch.from_numpy(scene.image).permute(2, 0, 1)[None]
    spec = psf_grid.study_lenses()["ideal"]
    return spec, psf_grid.measure(image, repeats=1, specs={"ideal": spec})


def test_one_default_per_knob_and_it_is_the_suites_geometry(ideal_records):
    spec, records = ideal_records
    default, _ = choose_geometry(spec)
    for knob in ("energy_fraction", "pupil_samples", "oversample"):
        (row,) = [r for r in records if r["knob"] == knob and r["default"]]
        assert (row["psf_size_px"], row["pupil_samples"], row["oversample"]) == (
            default.psf_size_px, default.pupil_samples, 0)  # 0: exact pixel integration


def test_finer_pixel_integration_and_wider_support_converge_to_the_reference(ideal_records):
    _, records = ideal_records
    over = sorted((r for r in records if r["knob"] == "oversample" and r["value"] > 0), key=lambda r: r["value"])
    assert all(a["psf_l1"] > b["psf_l1"] for a, b in zip(over, over[1:]))
    (exact,) = [r for r in records if r["knob"] == "oversample" and r["value"] == 0]
    assert exact["psf_l1"] < over[-1]["psf_l1"]  # the exact integral beats every midpoint rule
    energy = sorted((r for r in records if r["knob"] == "energy_fraction"), key=lambda r: r["value"])
    assert all(a["psf_size_px"] <= b["psf_size_px"] for a, b in zip(energy, energy[1:]))
    assert energy[-1]["image_psnr_db"] > energy[0]["image_psnr_db"] + 5
    assert records[0]["reference"]["energy_fraction"] > 0.99
    assert records[0]["reference"]["psf_size_px"] > max(r["psf_size_px"] for r in records)


def test_report_renders_the_study_chart(ideal_records, tmp_path):
    (tmp_path / "entries").mkdir()
    (tmp_path / "studies").mkdir()
    (tmp_path / "studies" / "psf_grid.json").write_text(json.dumps({"records": ideal_records[1]}))
    written = leaderboard_report.render(tmp_path)
    chart = tmp_path / "charts" / "psf_grid.png"
    assert chart in written and chart.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
    assert "charts/psf_grid.png" in (tmp_path / "charts.md").read_text()
