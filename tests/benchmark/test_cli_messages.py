"""The CLI and the Python API answer bad input with a sentence naming it, before any compute,
and the CLI explains itself at once (`--help` without torch,
examples, `list` with what each lens and attacker is, `run --help` with the attackers that run by
default)."""

from __future__ import annotations

import json
import os
import subprocess
import sys
from pathlib import Path

import pytest

import benchmark
from benchmark import api, cli

ROOT = Path(__file__).resolve().parents[2]
ENTRY = ROOT / "leaderboard" / "entries" / "gp__quick__synthetic.json"


def _python(code: str) -> subprocess.CompletedProcess:
    return subprocess.run([sys.executable, "-c", code], cwd=ROOT, capture_output=True, text=True, timeout=120)


# ---- help and list --------------------------------------------------------------------------------

@pytest.mark.slow
def test_help_imports_no_torch_and_shows_examples():
    """`python -m benchmark --help` answers without importing torch (3.2 s -> 0.13 s on a quiet
    2-core machine); the package's own import stays light too, its oneDNN bound set all the same."""
    done = _python("import sys, contextlib, io\n"
                   "import benchmark, benchmark.cli as cli\n"
                   "assert benchmark.__name__ and 'torch' not in sys.modules, 'import benchmark imported torch'\n"
                   "import os; assert os.environ['ONEDNN_PRIMITIVE_CACHE_CAPACITY']\n"
                   "out = io.StringIO()\n"
                   "with contextlib.redirect_stdout(out), contextlib.suppress(SystemExit):\n"
                   "    cli.main(['--help'])\n"
                   "assert 'torch' not in sys.modules, sorted(m for m in sys.modules if m.startswith('torch'))[:5]\n"
                   "print(out.getvalue())")
    assert done.returncode == 0, done.stderr[-2000:]
    assert "examples:" in done.stdout and "python -m benchmark run --lens ideal --profile smoke" in done.stdout


def test_mask_formats_the_parser_offers_are_the_exporters():
    from lenses.mask_export import FORMATS
    assert tuple(cli.MASK_FORMATS) == tuple(FORMATS)


def test_run_help_names_exactly_the_standard_chains_and_the_attackers_that_run_by_default(capsys):
    from benchmark.runner.defaults import CASCADE, STANDARD_ENSEMBLE, chain_parts
    with pytest.raises(SystemExit):
        cli.main(["run", "--help"])
    text = " ".join(capsys.readouterr().out.split()).replace("- ", "-")  # undo argparse's wrapping
    rows = cli.attacker_catalogue()
    default = [r["name"] for r in rows if r["runs_by_default"]]
    named = [r["name"] for r in rows if not r["runs_by_default"] and not r["standard_chains"]]
    assert "lpdr-craft" in named and "identity" in default and "lpdr" not in named
    # The ideal observer runs by default only as the cascade, on the plates no other chain read.
    assert "ideal-observer" not in named + default and CASCADE[0] in STANDARD_ENSEMBLE
    assert "default: the standard ensemble's chains (" + ", ".join(STANDARD_ENSEMBLE) + ")" in text
    assert ("with --all-chains: " + ", ".join(default) + ", every reader after every restorer, then the cascade "
            + ", ".join(CASCADE)) in text
    assert "; run only when named: " + ", ".join(named) in text
    assert all(r["standard_chains"] == [c for c in STANDARD_ENSEMBLE if r["name"] in chain_parts(c)] for r in rows)
    assert next(r for r in rows if r["name"] == "ideal-observer")["standard_chains"] == list(CASCADE)
    assert "one long native call" in text  # --budget-s says what it cannot stop


def test_list_json_describes_every_lens_and_attacker(capsys):
    import attacks
    import lenses
    assert cli.main(["list", "--json"]) == 0
    listing = json.loads(capsys.readouterr().out)
    by_name = {a["name"]: a for a in listing["attackers"]}
    assert set(by_name) == set(attacks.available())
    for row in by_name.values():
        assert row["description"] and row["threat_model"] in {t.value for t in attacks.ThreatModel}
    assert by_name["lpdr-craft"]["runs_by_default"] is False and by_name["identity"]["runs_by_default"] is True
    assert by_name["wiener-known-psf"]["threat_model"] == "lens-access"
    lens_rows = {r["name"]: r for r in listing["lenses"]}
    assert set(lens_rows) == set(lenses.available())
    assert all(r["description"] for r in lens_rows.values())
    assert lens_rows["gp"]["kind"] == "co-designed" and lens_rows["ideal"]["kind"] == "fixed"
    assert {s["name"] for s in listing["scene_sets"]} >= {"synthetic", "photos"}


def test_list_text_shows_threat_model_and_default(capsys):
    assert cli.main(["list"]) == 0
    lines = {line.split()[0]: line for line in capsys.readouterr().out.splitlines() if line.startswith("  ")}
    assert "lens-access" in lines["ideal-observer"] and " standard " in lines["ideal-observer"]
    assert "sensor-access" in lines["lpdr-craft"] and " named " in lines["lpdr-craft"]
    assert "sensor-access" in lines["lpdr-oracle"] and " all-chains " in lines["lpdr-oracle"]
    assert "lens-access" in lines["learned-reader"] and " standard " in lines["learned-reader"]


# ---- run arguments --------------------------------------------------------------------------------

@pytest.mark.parametrize("flags, named", [
    (["--seeds", "-1"], "--seeds"),
    (["--seeds", "12345678901234567890"], "--seeds"),
    (["--plate-format", ""], "--plate-format"),
    (["--plate-format", "LLX"], "--plate-format"),
])
def test_bad_run_arguments_exit_2_naming_the_option(flags, named, tmp_path, capsys):
    with pytest.raises(SystemExit) as stop:
        cli.main(["run", "--lens", "ideal", "--profile", "smoke", "--dry-run", "--out", str(tmp_path / "o"), *flags])
    assert stop.value.code == 2
    err = capsys.readouterr().err
    assert named in err and "Traceback" not in err
    assert not (tmp_path / "o").exists()


@pytest.mark.parametrize("kwargs, named", [
    ({"seeds": [-1]}, "seeds must lie in 0 .."),
    ({"seeds": [10**19]}, "seeds must lie in 0 .."),
    ({"plate_format": ""}, "plate format ''"),
])
def test_plan_refuses_what_a_run_would_fail_on(kwargs, named):
    with pytest.raises(ValueError, match=named):
        benchmark.plan(["ideal"], ["identity"], profile="smoke", **kwargs)


def test_ray_executor_without_ray_is_a_sentence(monkeypatch, capsys):
    monkeypatch.setitem(sys.modules, "ray", None)  # import ray raises ImportError
    assert cli.main(["run", "--lens", "ideal", "--attack", "identity", "--profile", "smoke", "--executor", "ray",
                     "--dry-run"]) == 2
    err = capsys.readouterr().err
    assert "executor 'ray'" in err and "pip install" in err and "'local'" in err


@pytest.mark.parametrize("kwargs, named", [
    ({"lenses": 5}, "lenses must be"),
    ({"lenses": ["ideal", 3]}, "lenses must be"),
    ({"profile": 1}, "profile must be"),
    ({"scenes": None}, "scenes must be a str"),
    ({"device": 0}, "device must be a str"),
    ({"seeds": "0,1"}, "seeds must be"),
    ({"plate_format": 7}, "plate_format must be a str or None"),
    ({"meta": "x"}, "meta must be a mapping"),
    ({"meta": {"when": object()}}, "meta must hold only what JSON can store"),
    ({"out": 3}, "out must be a folder path"),
])
def test_api_wrong_types_are_named_before_any_compute(kwargs, named, monkeypatch):
    def no_compute(*args, **kw):
        raise AssertionError("compute started before the arguments were checked")
    monkeypatch.setattr(api.runner, "run", no_compute)
    arguments = {"lenses": ["ideal"], "attacks": ["identity"], "profile": "smoke", **kwargs}
    with pytest.raises(TypeError, match=named):
        benchmark.run(**arguments)


# ---- export-mask --------------------------------------------------------------------------------

def test_export_mask_bad_outputs_and_inputs_exit_2_with_a_sentence(tmp_path, capsys):
    folder = tmp_path / "existing"
    folder.mkdir()
    assert cli.main(["export-mask", str(ENTRY), "--format", "npy", "--out", str(folder)]) == 2
    assert "is a folder; give the file to write" in capsys.readouterr().err

    listed = tmp_path / "list.json"
    listed.write_text("[1, 2]")
    assert cli.main(["export-mask", str(listed), "--format", "npy", "--out", str(tmp_path / "m.npy")]) == 2
    assert f"{listed} is not a leaderboard entry: it holds a JSON list" in capsys.readouterr().err

    blocker = tmp_path / "a_file"
    blocker.write_text("")
    target = blocker / "sub" / "m.npy"  # its parent cannot be created: an OSError at the CLI's boundary
    assert cli.main(["export-mask", str(ENTRY), "--format", "npy", "--out", str(target), "--samples", "9"]) == 2
    err = capsys.readouterr().err
    assert err.startswith("error: cannot use ") and str(blocker) in err and "Traceback" not in err

    assert cli.main(["export-mask", str(ENTRY), "--format", "npy", "--out", str(tmp_path / "big.npy"),
                     "--samples", "100000"]) == 2
    err = capsys.readouterr().err
    assert "--samples must lie in 5 .. 8193" in err and "74.5 GiB" in err
    assert not (tmp_path / "big.npy").exists() and not (tmp_path / "m.npy").exists()


@pytest.mark.skipif(os.geteuid() == 0, reason="root writes into read-only folders; the message is checked "
                    "through an unwritable parent instead (test above)")
def test_export_mask_to_a_read_only_folder_names_it(tmp_path, capsys):
    folder = tmp_path / "ro"
    folder.mkdir()
    folder.chmod(0o500)
    try:
        assert cli.main(["export-mask", str(ENTRY), "--format", "npy", "--out", str(folder / "m.npy"),
                         "--samples", "9"]) == 2
    finally:
        folder.chmod(0o700)
    err = capsys.readouterr().err
    assert str(folder) in err and "Permission denied" in err and "write elsewhere" in err


@pytest.mark.slow
def test_a_cache_that_cannot_be_written_is_a_sentence_naming_it(tmp_path):
    blocker = tmp_path / "not_a_folder"
    blocker.write_text("")
    env = {**os.environ, "PLB_CACHE": str(blocker / "cache")}
    done = subprocess.run([sys.executable, "-m", "benchmark", "-q", "run", "--lens", "ideal", "--attack", "identity",
                           "--profile", "smoke", "--dry-run"], cwd=ROOT, env=env, capture_output=True, text=True,
                          timeout=300)
    assert done.returncode == 2, done.stderr[-2000:]
    assert "error: cannot use " + str(blocker) in done.stderr and "Traceback" not in done.stderr


def test_export_mask_refuses_to_co_design_an_uncached_lens_without_train(tmp_path, monkeypatch, capsys):
    """A co-designed lens the cache and the package do not hold is refused (nothing trained, nothing
    written to the cache); the shipped gp seed 0 still exports without --train."""
    cache = tmp_path / "cache"
    monkeypatch.setenv("PLB_CACHE", str(cache))
    assert cli.main(["export-mask", "gp", "--seed", "7", "--format", "npy", "--out", str(tmp_path / "m7.npy")]) == 2
    err = capsys.readouterr().err
    assert "'gp' (profile quick, seed 7) is neither in the cache nor shipped" in err and "--train" in err
    assert not (tmp_path / "m7.npy").exists()
    assert not any(p.is_file() for p in cache.rglob("*"))
    assert cli.main(["export-mask", "gp", "--format", "npy", "--out", str(tmp_path / "m0.npy"), "--samples", "9"]) == 0
    assert (tmp_path / "m0.npy").is_file()
