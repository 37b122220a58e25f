"""`python -m benchmark export-mask`: a published entry's mask, read back, equals its Zernike sum."""

from __future__ import annotations

import json
import logging

import numpy as np
import pytest

from benchmark import cli
from benchmark.results.entries import LEADERBOARD
from lenses.zernike import zernike_noll

ENTRY = LEADERBOARD / "entries" / "gp__quick__synthetic.json"


def test_entry_mask_round_trips_through_the_cli(tmp_path, capsys):
    out = tmp_path / "gp.npy"
    assert cli.main(["-q", "export-mask", str(ENTRY), "--format", "npy", "--out", str(out), "--samples", "65"]) == 0
    assert "wrote" in capsys.readouterr().out
    assert logging.getLogger().level == logging.WARNING  # -q
    spec = json.loads(ENTRY.read_text())["lens_spec"]
    coefficients = spec["mask"]["zernike_um"]
    radius_mm = spec["optics"]["aperture_diameter_mm"] / 2
    meta = json.loads((tmp_path / "gp.npy.json").read_text())
    assert meta["lens"] == "gp" and meta["zernike_um"] == coefficients and meta["format"] == "npy"
    c = np.linspace(-radius_mm, radius_mm, 65)
    x, y = np.meshgrid(c, c[::-1])
    rho, theta = np.hypot(x, y) / radius_mm, np.arctan2(y, x)
    expected = sum(cj * zernike_noll(j, rho, theta) for j, cj in enumerate(coefficients, start=1))
    data = np.load(out)
    inside = rho <= 1
    np.testing.assert_allclose(data[inside], expected[inside], atol=1e-12)


def test_bad_inputs_exit_with_a_named_error(tmp_path, capsys):
    assert cli.main(["export-mask", "no-such-lens", "--format", "npy", "--out", str(tmp_path / "m.npy")]) == 2
    assert "unknown lens 'no-such-lens'" in capsys.readouterr().err
    assert cli.main(["export-mask", str(ENTRY), "--format", "csv", "--out", str(tmp_path / "m.csv"),
                     "--samples", "3"]) == 2
    assert "at least 5 samples" in capsys.readouterr().err
    with pytest.raises(SystemExit):
        cli.main(["export-mask", str(ENTRY), "--format", "stl", "--out", str(tmp_path / "m.stl")])
