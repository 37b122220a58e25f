"""The co-designed lens shipped in the package (benchmark.codesign.shipped, `ship-lens`): it is the run
a quick `run --lens gp` asks for, a fresh cache loads it and its known-pairs NAFNet instead of training,
both re-measure the checks their provenance records, and a damaged or mismatched copy is refused."""

from __future__ import annotations

import json
import shutil

import pytest
import torch

from attacks.restorers.nafnet_known_pairs import NafnetKnownPairs
from attacks.training.shipped_weights import SHIPPED_DIR as ATTACK_WEIGHTS
from benchmark.codesign.codesigned_lenses import attach
from benchmark.codesign.shipped import SHIPPED_DIR, ShippedLensError, install_shipped
from benchmark.publish.ship_lens import codesign_run, known_pairs_check, lens_check, run_config
from benchmark.store.profiles import PROFILES
from benchmark.runner.tasks import fit_context
from lenses.spec import load_spec

QUICK = PROFILES["quick"]


@pytest.fixture
def fresh_cache(tmp_path, monkeypatch):
    monkeypatch.setenv("PLB_CACHE", str(tmp_path / "cache"))
    return tmp_path / "cache"


def _provenance(folder_name: str) -> dict:
    return json.loads((SHIPPED_DIR / folder_name / "shipped.json").read_text())


def test_the_shipped_gp_is_the_run_a_quick_gp_run_asks_for(fresh_cache):
    run = codesign_run("gp", QUICK, 0)
    assert (SHIPPED_DIR / run.directory.name).is_dir(), (
        f"no shipped co-design {run.directory.name}: the quick gp configuration changed; remake it with "
        "`python -m benchmark ship-lens gp` (else a fresh quick gp run co-designs it, about 6 minutes)")
    assert _provenance(run.directory.name)["config"] == json.loads(json.dumps(run.config))


@pytest.mark.slow
def test_a_fresh_cache_loads_the_shipped_gp_and_its_known_pairs_nafnet(fresh_cache):
    run = codesign_run("gp", QUICK, 0)
    assert not run.directory.exists()
    trained = run.load()
    assert trained is not None and run.directory.is_dir()
    shipped_spec = load_spec(SHIPPED_DIR / run.directory.name / "lens.toml")
    assert torch.allclose(trained.lens.coefficients_um.detach().double(),
                          torch.tensor(shipped_spec.mask.zernike_um, dtype=torch.float64))
    lens = attach(trained)
    recorded = _provenance(run.directory.name)["made"]["check"]
    # Same code and weights: the same mIoU up to float rounding across CPUs.
    assert lens_check(lens, "gp", QUICK, 0)["miou"] == pytest.approx(recorded["miou"], abs=0.005)

    ctx = fit_context(lens, run_config("gp", QUICK, 0), 0, None)
    attacker = NafnetKnownPairs(backend="torch")
    attacker.fit(ctx)
    assert attacker.shipped is not None and attacker.trained is False
    assert attacker.describe()["shipped_weights"]["file"] == "nafnet-known-pairs-gp-quick-s0.safetensors"
    made = json.loads((ATTACK_WEIGHTS / "nafnet-known-pairs-gp-quick-s0.json").read_text())["made"]["check"]
    check = known_pairs_check(attacker, ctx)
    assert check["psnr_in_db"] == pytest.approx(made["psnr_in_db"], abs=0.01)
    assert check["psnr_out_db"] == pytest.approx(made["psnr_out_db"], abs=0.05)
    assert check["psnr_out_db"] > check["psnr_in_db"] + 3  # it restores, it is no identity


def test_without_use_shipped_a_fresh_cache_has_no_run(fresh_cache):
    assert codesign_run("gp", QUICK, 0, use_shipped=False).load() is None


def _copy(tmp_path, run) -> tuple:
    source = SHIPPED_DIR / run.directory.name
    directory = tmp_path / "shipped"
    shutil.copytree(source, directory / source.name)
    return directory, directory / source.name


def test_a_damaged_shipped_file_is_named_and_nothing_reaches_the_cache(fresh_cache, tmp_path):
    run = codesign_run("gp", QUICK, 0)
    directory, copy = _copy(tmp_path, run)
    spec = copy / "lens.toml"
    spec.write_bytes(spec.read_bytes().replace(b"=", b"=-", 1))
    with pytest.raises(ShippedLensError, match="lens.toml.*damaged"):
        install_shipped(run.directory, run.config, directory)
    assert not run.directory.exists()
    (copy / "utility.safetensors").unlink()
    spec.write_bytes((SHIPPED_DIR / copy.name / "lens.toml").read_bytes())
    with pytest.raises(ShippedLensError, match="utility.safetensors.*missing"):
        install_shipped(run.directory, run.config, directory)
    assert not run.directory.exists()


def test_a_shipped_folder_of_another_configuration_is_refused(fresh_cache, tmp_path):
    run = codesign_run("gp", QUICK, 0)
    directory, _ = _copy(tmp_path, run)
    with pytest.raises(ShippedLensError, match="configuration is not the run's"):
        install_shipped(run.directory, {**run.config, "seed": 1}, directory)
    assert not run.directory.exists()
    assert install_shipped(run.directory.with_name("gp-0000000000000000"), run.config, directory) is False
