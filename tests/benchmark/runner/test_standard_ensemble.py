"""The standard ensemble (benchmark.runner.defaults.STANDARD_ENSEMBLE) is the run's default:
only its chains are measured, a restorer no chain reads never has its plate windows restored, and
`--attack` / `all_chains` still give exactly what they name (every reader after every restorer)."""

from __future__ import annotations

import pytest
import torch

import attacks
from benchmark import api
from benchmark.runner.defaults import (
    CASCADE, LEARNED_READER, MEASURED_ADDITIONS, MEASURED_READERS, RUN_PROPOSAL, STANDARD_ENSEMBLE, chain_parts)
from benchmark.runner import runner
from benchmark.runner.config import RunConfig
from benchmark.runner.evaluation import (
    Attacked, PlateSet, ReadyReader, Target, read_sensor, run_reader, run_restorers)
from benchmark.runner.planning import run_directory
from benchmark.results.schema import cascade_name
from benchmark.runner.rows import RowBuilder
from benchmark.runner.sensing import to_tensor
from benchmark.scenes import load_scenes
from benchmark.store.profiles import get_profile


class Counting(attacks.Restorer):
    threat_model = attacks.ThreatModel.SENSOR_ACCESS

    def __init__(self, name: str) -> None:
        super().__init__()
        self.name = name  # type: ignore[misc]
        self.shapes: list[tuple[int, ...]] = []

    def restore(self, sensor: torch.Tensor) -> torch.Tensor:
        self.shapes.append(tuple(sensor.shape))
        return sensor.flip(-1)


class Blind(attacks.Reader):
    name = "blind"
    threat_model = attacks.ThreatModel.SENSOR_ACCESS

    def read(self, images, hints=None):
        return [[] for _ in range(images.shape[0])]


def _evaluate(chains, fit_s=None, rows_out=None):
    cfg = RunConfig(["fake"], None, "synthetic", get_profile("smoke"), [0], chains=chains)
    scenes = load_scenes("synthetic", "val", 3, (64, 128), 0)
    sensor = to_tensor(scenes)
    windows = [sensor[0, :, :32, :48].clone(), sensor[1, :, 8:40, 16:80].clone()]
    plates = PlateSet(scenes=scenes[:2], sharp=windows, sensor=windows, n_frames=2)
    target = Target("fake", scenes, sensor, sensor, attacks.FitContext(), None, None, plates=plates)
    read, unread = Counting("read"), Counting("unread")
    out = Attacked()
    builder = RowBuilder(cfg, "fake", 0, {"lens": "fake"}, {"device": "cpu"})
    ready = [ReadyReader(Blind(), None, {"name": "blind"}, fit_s=fit_s)]
    read_sensor(target, ready, cfg, builder, out)
    run_restorers(target, [read, unread], {}, cfg, builder, out, ready)
    out.finish()
    if rows_out is not None:
        rows_out.extend(out.rows)
    return [r.attack for r in out.rows], read, unread, sensor.shape


@pytest.mark.slow
def test_only_the_chains_of_the_ensemble_are_read_and_their_restorers_windows_restored():
    attacks_measured, read, unread, frames = _evaluate(("read", "unread", "blind", "read>blind"))
    assert attacks_measured == ["read", "unread", "blind", "read>blind"]
    # Both restorers are scored on the frames; only the one a chain reads restores the plate windows.
    assert [s for s in unread.shapes if s[-2:] != frames[-2:]] == []
    assert [s for s in read.shapes if s[-2:] != frames[-2:]]
    everything, *_ = _evaluate(None)  # the full cross product
    assert sorted(everything) == sorted(["read", "unread", "blind", "read>blind", "unread>blind"])


@pytest.mark.slow
def test_a_readers_fit_is_carried_once_by_its_first_row_its_own_or_else_its_first_chain():
    """A reader whose row on the sensor image the run does not measure (it reads only after restorers) still
    has its fit seconds in the results: on the first chain read with it, and on no other row."""
    for chains, carrier in ((("read", "unread", "blind", "read>blind", "unread>blind"), "blind"),
                            (("read", "unread", "read>blind", "unread>blind"), "read>blind")):
        rows: list = []
        _evaluate(chains, fit_s=7.0, rows_out=rows)
        assert [r.attack for r in rows if "fit_s" in r.metrics and r.reader == "blind"] == [carrier], chains


@pytest.mark.slow
def test_the_sharp_scenes_are_read_by_every_reader_the_run_reads_with():
    """The sharp reference (no lens, nothing restores it) is read by a reader the ensemble runs only after
    restorers, as it is; a reader no chain of the run reads with is neither fitted nor read."""
    scenes = load_scenes("synthetic", "val", 2, (64, 128), 0)
    sharp = to_tensor(scenes)
    windows = [sharp[0, :, :32, :48].clone(), sharp[1, :, 8:40, 16:80].clone()]
    target = Target("sharp", scenes, sharp, sharp, attacks.FitContext(), None, None,
                    plates=PlateSet(scenes=scenes, sharp=windows, sensor=windows, n_frames=2))
    for chains, expected in ((("read", "read>blind"), ["blind"]), (("read", "read>other"), [])):
        cfg = RunConfig(["sharp"], None, "synthetic", get_profile("smoke"), [0], chains=chains)
        out = Attacked()
        run_reader(target, Blind(), cfg, RowBuilder(cfg, "sharp", 0, {"lens": "sharp"}, {"device": "cpu"}), out)
        assert [r.attack for r in out.rows] == expected, chains
        assert all(r.kind == "reader" and r.ok for r in out.rows)


def test_the_standard_ensemble_is_the_rule_re_applied_to_fresh_runs_of_the_privacy_lenses():
    """``RUN_PROPOSAL`` is what the rule keeps on the chain effects of the full cross product of the five privacy
    lenses (leaderboard/studies/run_pairing.json), completed on those runs' per-unit outcomes (kept in git,
    leaderboard/studies/cross_product), recomputed here; dropping every other chain at once moves no run's
    ensemble past the rule's thresholds."""
    import json
    from pathlib import Path

    from benchmark.results.ensemble_choice import PLATE_POINTS, PSNR_DB
    from benchmark.studies.run_pairing_study import PRIVACY_LENSES, proposal, read_results

    root = Path(__file__).resolve().parents[3]
    record = json.loads((root / "leaderboard" / "studies" / "run_pairing.json").read_text())
    assert set(record["proposal"]["lenses"]) == set(PRIVACY_LENSES)
    runs = {}
    for lens in PRIVACY_LENSES:
        kept = root / record["lenses"][lens]["run"]["folder"]
        assert kept.is_file(), f"{lens}: the run the proposal was chosen on is not kept in git ({kept})"
        runs[lens] = [r for r in read_results(kept).rows if r.lens == lens and r.seed == record["seed"]]
    again = proposal(record, runs)
    for key in ("rule", "added_jointly", "chains", "dropped", "joint_removal"):
        assert again[key] == record["proposal"][key], key
    assert set(RUN_PROPOSAL) == set(again["chains"])
    for lens, joint in again["joint_removal"].items():
        assert joint["plate_points"] <= PLATE_POINTS and joint["psnr_db"] <= PSNR_DB, (lens, joint)
    assert set(STANDARD_ENSEMBLE) == set(RUN_PROPOSAL) | {"raw"}
    assert len(STANDARD_ENSEMBLE) == len(set(STANDARD_ENSEMBLE))
    assert STANDARD_ENSEMBLE[-1:] == CASCADE and set(CASCADE) <= set(RUN_PROPOSAL)
    named = runner.standard_attackers()
    assert len(named) == len(set(named)) and set(named) == {p for c in STANDARD_ENSEMBLE for p in chain_parts(c)}
    # Every reader chain of the ensemble reads with a reader, after a restorer that is in it.
    for chain in STANDARD_ENSEMBLE:
        if ">" in chain:
            restorer, reader = chain.split(">")
            assert isinstance(attacks.load(restorer), attacks.Restorer) and isinstance(attacks.load(reader), attacks.Reader)
            assert restorer in STANDARD_ENSEMBLE


def test_default_attackers_are_the_standard_ensemble_and_named_ones_are_exactly_what_they_name(tmp_path):
    cfg, selection = api._configure(["ideal"], None, "smoke", [0], "synthetic", "cpu", "local", None, 30, None)
    assert cfg.chains == STANDARD_ENSEMBLE
    assert {r.name for r in selection.restorers + selection.readers} == set(runner.standard_attackers())
    named, _ = api._configure(["ideal"], ["wiener-known-psf", "lpdr"], "smoke", [0], "synthetic", "cpu", "local",
                              None, 30, None)
    assert named.chains is None and named.wants("wiener-known-psf>lpdr")
    full, chosen = api._configure(["ideal"], None, "smoke", [0], "synthetic", "cpu", "local", None, 30, None,
                                  all_chains=True)
    # The full cross product of the attackers that run by default, then the standard ensemble's cascade.
    restorers, readers = [r.name for r in chosen.restorers], [r.name for r in chosen.readers]
    assert "identity" in restorers and set(chain_parts(CASCADE[0])) <= set(readers)
    crossed = [r for r in readers if cascade_name(r) not in CASCADE]
    assert full.chains is not None and full.chains[-len(CASCADE):] == CASCADE
    assert set(full.chains) == {*restorers, *crossed, *(f"{a}>{b}" for a in restorers for b in crossed), *CASCADE}
    assert not any(full.wants(f"{a}>{chain_parts(CASCADE[0])[0]}") for a in restorers)  # a cascade only
    # Two runs that measure different chains never share task results.
    cfg.cache_dir = full.cache_dir = tmp_path
    assert run_directory(cfg, selection.restorers, selection.readers) != run_directory(
        RunConfig(**{**cfg.__dict__, "chains": None}), selection.restorers, selection.readers)
    with pytest.raises(TypeError, match="all_chains"):
        api._configure(["ideal"], None, "smoke", [0], "synthetic", "cpu", "local", None, 30, None, all_chains="yes")


def test_each_measured_addition_beat_every_published_restorer_on_the_study_s_lenses():
    import json
    from pathlib import Path

    study = json.loads((Path(__file__).resolve().parents[3] / "leaderboard" / "studies" / "known_psf_restorers.json")
                       .read_text())
    for addition in (c for c in MEASURED_ADDITIONS if ">" not in c):
        records = [lens["restorers"][addition] for lens in study["lenses"].values() if addition in lens["restorers"]]
        assert records, f"{addition}: no lens of the study measured it"
        for record in records:
            assert record["versus_published_ensemble"]["verdict"] == "holds"
            assert all(c["verdict"] == "holds" for c in record["versus_published"].values()
                       if c["difference_db"] != 0.0)


def test_each_measured_reader_raises_the_published_ensemble_by_more_than_the_rules_point():
    """On the published entries' own plates (paired by plate id, from 32 px, seed 0), adding the reader
    raises the entry's ensemble by more than 1 point (the rule that keeps a chain), significantly, on
    some lens of the study; and it never needs the plates to be re-drawn (every lens paired)."""
    import json
    from pathlib import Path

    study = json.loads((Path(__file__).resolve().parents[3] / "leaderboard" / "studies" / "psf_reader.json").read_text())
    assert {"ideal", "defocus", "gp", "os", "os-d-1000"} <= set(study["lenses"])
    assert all(lens["paired"] for lens in study["lenses"].values())
    for reader in MEASURED_READERS:
        gains = [lens["paired_from_32px"]["ensemble with it - published ensemble"] for lens in study["lenses"].values()]
        assert any(g["verdict"] == "holds" and g["difference_pt"] > 1.0 for g in gains), (reader, gains)
        assert all(g["difference_pt"] >= 0.0 for g in gains)


def test_the_fine_tuned_learned_reader_keeps_its_place_beside_the_family_trained_psf_reader():
    """The per-lens fine-tune costs minutes; the ensemble runs it (after restorers, where the cross product
    kept it) only while, with learned-reader-psf in the ensemble, it still adds more than 1 point
    significantly on some lens of the study (on ideal and os)."""
    import json
    from pathlib import Path

    study = json.loads((Path(__file__).resolve().parents[3] / "leaderboard" / "studies" / "psf_reader.json").read_text())
    adds = [lens["paired_from_32px"]["ensemble with it - the same without learned-reader"]
            for lens in study["lenses"].values()]
    assert any(LEARNED_READER in chain_parts(chain) for chain in STANDARD_ENSEMBLE)  # read after restorers
    assert any(a["verdict"] == "holds" and a["difference_pt"] > 1.0 for a in adds), adds


def test_the_per_lens_fine_tune_of_the_psf_reader_joins_the_ensemble_only_where_it_pays():
    """``learned-reader-psf-tuned`` costs a fine-tune per lens (about 100-200 steps); it is in the standard
    ensemble exactly when, on the study's plates, the ensemble with it in place of the zero-shot reader reads
    more than 1 point more, significantly, on some lens (the rule that keeps a chain)."""
    import json
    from pathlib import Path

    from attacks.readers.learned_reader_psf import LearnedReaderPSFTuned

    study = json.loads((Path(__file__).resolve().parents[3] / "leaderboard" / "studies" / "psf_reader.json").read_text())
    gains = [lens["paired_from_32px"]["ensemble with it tuned - ensemble with it"] for lens in study["lenses"].values()]
    pays = any(g["verdict"] == "holds" and g["difference_pt"] > 1.0 for g in gains)
    assert (LearnedReaderPSFTuned.name in STANDARD_ENSEMBLE) == pays, gains
    assert LearnedReaderPSFTuned.run_by_default == pays
