"""The run-pairing study: an entry paired with itself differs by nothing; a run with other plates is not paired."""

from __future__ import annotations

import dataclasses
import gzip
import json

import pytest

from benchmark.results.entries import read_entry
from benchmark.results.schema import Results
from benchmark.studies import run_pairing_study
from benchmark.studies.run_pairing_study import LEADERBOARD, pair_lens


def entry(lens: str):
    return read_entry(LEADERBOARD / "entries" / f"{lens}__quick__synthetic.json")


def test_an_entry_paired_with_itself_differs_by_nothing(tmp_path):
    gp = entry("gp")
    rows = gp.rows
    record = pair_lens(rows, "gp", 0, None)
    plates, scenes = record["plates"], record["scenes"]
    assert plates["paired"] and scenes["paired"]
    assert plates["from_32px"]["run"] == plates["from_32px"]["entry"]
    assert plates["from_32px"]["run - entry"]["difference"] == 0.0 and plates["entry_missed"] >= 0
    assert all(not count for count in plates["chains_on_plates_the_entry_missed"].values())
    assert scenes["run_db"] == scenes["entry_db"] and scenes["run - entry"]["difference"] == 0.0
    assert sum(b["n"] for b in plates["bins"].values()) == plates["n_plates"]
    # The command: a run folder holding the entry's rows as its results.
    (tmp_path / "run").mkdir()
    (tmp_path / "run" / "results.json").write_text(json.dumps(Results(rows, gp.settings).to_json()))
    out = tmp_path / "pairing.json"
    assert run_pairing_study.main(["--run", str(tmp_path / "run"), "--lens", "gp", "--out", str(out),
                                   "--baseline", str(tmp_path / "run")]) == 0
    written = json.loads(out.read_text())["lenses"]["gp"]
    assert written["plates"]["paired"]
    # Against a baseline run: the same comparison, run against run; the run against itself differs by nothing.
    against = written["against_baseline"]
    assert against["plates_from_px"]["run - entry"]["difference"] == 0.0
    assert against["scenes"]["run - entry"]["difference"] == 0.0 and "run_restorers_db" not in against["scenes"]


def test_a_gzipped_results_file_reads_as_its_run_folder_and_a_corrupt_one_names_itself(tmp_path):
    gp = entry("gp")
    text = json.dumps(Results(gp.rows, gp.settings).to_json())
    (tmp_path / "run").mkdir()
    (tmp_path / "run" / "results.json").write_text(text)
    (tmp_path / "gp.json.gz").write_bytes(gzip.compress(text.encode()))
    folder, packed = run_pairing_study.read_results(tmp_path / "run"), run_pairing_study.read_results(tmp_path / "gp.json.gz")
    assert [r.to_json() for r in packed.rows] == [r.to_json() for r in folder.rows] and len(folder.rows) == len(gp.rows)
    (tmp_path / "bad.json.gz").write_bytes(gzip.compress(b'{"rows": 3}'))
    with pytest.raises(SystemExit, match="not a run's results: .*bad.json.gz"):
        run_pairing_study.read_results(tmp_path / "bad.json.gz")
    with pytest.raises(SystemExit, match="neither a run folder"):
        run_pairing_study.read_results(tmp_path / "missing")


def test_a_run_with_other_plates_is_reported_not_paired():
    rows = entry("gp").rows
    renamed = [dataclasses.replace(r, units=dataclasses.replace(r.units, prefix="other:"))
               if r.units is not None and r.units.unit == "plate" else r for r in rows]
    record = pair_lens(renamed, "gp", 0, None)
    assert not record["plates"]["paired"] and record["plates"]["why"] == "plate ids differ"


def test_the_proposal_keeps_what_matters_and_drops_jointly_no_less_than_alone():
    from benchmark.results.ensemble_choice import PLATE_POINTS, PSNR_DB

    gp = entry("gp")
    rows = [r for r in gp.rows if r.seed == 0]
    record = {"lenses": {"gp": pair_lens(gp.rows, "gp", 0, None)}}
    effects = record["lenses"]["gp"]["chain_effects"]
    found = run_pairing_study.proposal(record, {"gp": rows})
    assert found["lenses"] == ["gp"]
    kept, dropped = set(found["chains"]), set(found["dropped"])
    assert not kept & dropped and kept | dropped >= set(effects)
    assert {c for c, e in effects.items() if e["matters"]} <= kept and "lpdr" in kept
    assert f"{found['strongest_restorer']}>lpdr" in kept
    assert all(not effects[c]["matters"] for c in dropped)
    # Dropping every other chain together loses at least what dropping any one of them alone loses.
    joint = found["joint_removal"]["gp"]
    assert joint["plate_points"] >= max(effects[c]["plate_points"] for c in dropped) - 1e-9
    assert joint["psnr_db"] >= max(effects[c]["psnr_db"] for c in dropped) - 1e-9
    # ... and the completion leaves that within the rule's thresholds; the rule's own chains are all kept.
    assert joint["plate_points"] <= PLATE_POINTS and joint["psnr_db"] <= PSNR_DB
    assert set(found["rule"]) <= kept and set(found["added_jointly"]) <= kept


def test_runs_of_different_lenses_named_together_each_pair_their_own_lens(tmp_path):
    """`--run A --run B --lens a --lens b`: a run that does not hold a named lens leaves that lens to the run
    that does (it once replaced it with nothing)."""
    for lens in ("gp", "defocus"):
        e = entry(lens)
        (tmp_path / lens).mkdir()
        (tmp_path / lens / "results.json").write_text(json.dumps(Results(e.rows, e.settings).to_json()))
    out = tmp_path / "pairing.json"
    assert run_pairing_study.main(["--run", str(tmp_path / "gp"), "--run", str(tmp_path / "defocus"), "--lens", "gp",
                                   "--lens", "defocus", "--out", str(out)]) == 0
    written = json.loads(out.read_text())["lenses"]
    for lens in ("gp", "defocus"):
        assert written[lens]["plates"]["paired"] and written[lens]["run"]["folder"] == str(tmp_path / lens)
