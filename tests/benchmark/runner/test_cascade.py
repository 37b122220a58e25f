"""The cascade (benchmark.runner.cascade): a reader run last, only on the plates no chain before it read,
in the width bins still open, widest first, up to its plate budget; the ensemble counts each plate once."""

from __future__ import annotations

import torch

import attacks
from attacks.registry import load
from benchmark.results.ensemble import plate_ensemble
from benchmark.results.plate_scoring import scored
from benchmark.results.schema import cascade_name
from benchmark.runner.cascade import OPEN_BIN_BELOW, choose, run_cascade, wanted_readers, width_bin
from benchmark.runner.config import RunConfig
from benchmark.runner.defaults import STANDARD_ENSEMBLE, chain_parts
from benchmark.runner.evaluation import Attacked, PlateSet, ReadyReader, Target, read_sensor
from benchmark.runner.rows import RowBuilder
from benchmark.runner.sensing import to_tensor
from benchmark.scenes import load_scenes
from benchmark.store.profiles import get_profile


def _record(scene: str, width: int, correct: bool) -> dict:
    return {"scene": scene, "width_px": width, "correct": correct}


def test_choose_takes_unread_plates_of_open_bins_widest_first_up_to_the_limit():
    # Bin 64-96 px: 1 of 2 read (open); bin 96-128: 3 of 4 read (at OPEN_BIN_BELOW or above: closed).
    records = [_record("a", 70, True), _record("b", 90, False),
               *[_record(s, 100, s != "f") for s in ("c", "d", "e", "f")],
               _record("b", 90, False)]  # a second chain's record of the same plate
    names, widths = ["a", "b", "c", "d", "e", "f", "g", "h"], [70, 90, 100, 100, 100, 100, 20, 40]
    share, pick = choose(records, names, widths, limit=10)
    assert share[width_bin(70)] == 0.5 and share[width_bin(100)] == 0.75 >= OPEN_BIN_BELOW
    # b (unread, open bin), then g and h (bins no chain scored: open), widest first; f's bin is closed.
    assert pick == [1, 7, 6]
    assert choose(records, names, widths, limit=2)[1] == [1, 7]
    assert choose(records, names, [-1] * 8, limit=10)[1] == []  # windows without a scored plate
    # From `every_from_px` every unread plate of an open bin is given, past the limit; narrower ones only within it.
    assert choose(records, names, widths, limit=0, every_from_px=32)[1] == [1, 7]
    assert choose(records, names, widths, limit=1, every_from_px=80)[1] == [1]
    assert choose(records, names, widths, limit=3, every_from_px=80)[1] == [1, 7, 6]


class Peeking(attacks.Reader):
    """A test reader that reads a window exactly when its index is in `knows` (it looks the window up)."""

    threat_model = attacks.ThreatModel.SENSOR_ACCESS
    hints = frozenset({"plate_boxes"})

    def __init__(self, name: str, windows: list[torch.Tensor], scenes, knows: set[int]) -> None:
        super().__init__()
        self.name = name  # type: ignore[misc]
        self.windows, self.scenes, self.knows = windows, scenes, knows
        self.given: list[int] = []

    def read(self, images, hints=None):
        out = []
        for image, boxes in zip(images, hints.plate_boxes):
            j = next(k for k, w in enumerate(self.windows) if w.shape == image.shape and torch.equal(w, image))
            self.given.append(j)
            texts = [p.text if j in self.knows else "WRONG00" for p in self.scenes[j].plates]
            out.append([attacks.PlateRead(t, tuple(b), 1.0) for t, b in zip(texts, boxes)])
        return out


def test_the_cascade_reads_only_what_the_chains_before_missed_and_the_ensemble_counts_each_plate_once():
    scenes = [s for s in load_scenes("synthetic", "val", 12, (128, 256), 0) if any(map(scored, s.plates))][:6]
    windows = list(to_tensor(scenes))
    plates = PlateSet(scenes=scenes, sharp=windows, sensor=windows, n_frames=len(scenes))
    target = Target("fake", scenes, torch.stack(windows), torch.stack(windows), attacks.FitContext(), None, None,
                    plates=plates)
    cheap = Peeking("cheap", windows, scenes, knows={0, 1})
    costly = Peeking("costly", windows, scenes, knows=set(range(len(scenes))))
    cfg = RunConfig(["fake"], None, "synthetic", get_profile("smoke"), [0], chains=("cheap", cascade_name("costly")))
    builder = RowBuilder(cfg, "fake", 0, {"lens": "fake"}, {"device": "cpu"})
    out = Attacked()
    ready = [ReadyReader(cheap, None, {"name": "cheap"}), ReadyReader(costly, None, {"name": "costly"})]
    read_sensor(target, ready, cfg, builder, out)
    out.finish()
    assert [r.attack for r in out.rows] == ["cheap"] and costly.given == []  # not a chain of its own
    (cascading,) = wanted_readers(cfg, ready)
    run_cascade(target, cascading, cfg, builder, out, plates_per_lens=3)
    row = out.rows[-1]
    assert (row.kind, row.attack, row.reader, row.ok) == ("reader", "cascade:costly", "costly", True)
    # Given the three widest windows cheap did not read (every bin is open: cheap read 2 of 6 windows).
    widths = {j: max(p.box_xyxy[2] - p.box_xyxy[0] for p in scenes[j].plates if scored(p)) for j in range(6)}
    expected = sorted(set(range(6)) - {0, 1}, key=lambda j: (-widths[j], j))[:3]
    assert costly.given == expected and row.metrics["cascade_given"] == 3
    # Its units hold every scored plate: the plates it was given read, the others not.
    read_by = dict(zip(row.units.names(), row.units.values["correct"]))
    given_plates = {f"{scenes[j].name}#{k}" for j in expected for k in range(sum(map(scored, scenes[j].plates)))}
    assert {n for n, c in read_by.items() if c} == given_plates
    ensemble = plate_ensemble(out.rows, bins_px=(0,))
    (seed,) = ensemble.per_seed
    union = seed.read.any(axis=0)
    cheap_read = seed.read[seed.chains.index("cheap")]
    cascade_read = seed.read[seed.chains.index("cascade:costly")]
    assert not (cheap_read & cascade_read).any()  # each plate read by one stage, counted once
    assert union.sum() == cheap_read.sum() + cascade_read.sum()
    only = {c.attack: c.only for c in ensemble.contributions}
    assert only["cascade:costly"] == cascade_read.sum() > 0


def test_the_cascade_is_in_the_standard_ensemble_and_runs_a_registered_reader():
    (cascade,) = [c for c in STANDARD_ENSEMBLE if c.startswith("cascade:")]
    assert STANDARD_ENSEMBLE[-1] == cascade and chain_parts(cascade) == ["ideal-observer"]
    assert isinstance(load("ideal-observer"), attacks.Reader)
    cfg = RunConfig(["x"], None, "synthetic", get_profile("smoke"), [0], chains=None)
    assert wanted_readers(cfg, [ReadyReader(Peeking("ideal-observer", [], [], set()), None)]) == []  # all chains
