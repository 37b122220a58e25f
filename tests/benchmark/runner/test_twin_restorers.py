"""Restorers with one `restoration_key` (the same images for every input, e.g. a fine-tune that kept its
start) are restored once per evaluation: the later one is scored from the earlier one's output, and its rows
are those a restoration of its own gives."""

from __future__ import annotations

import pytest
import torch

import attacks
from benchmark.runner.evaluation import RESTORED_AS, Attacked, ReadyReader, run_restorers
from window_target import small_target  # tests/window_target.py


class _Keyed(attacks.Restorer):
    """Darkens its input by `factor`; counts the images it restored; claims `key`."""

    threat_model = attacks.ThreatModel.SENSOR_ACCESS

    def __init__(self, name: str, key: str | None, factor: float = 0.9, broken_key: bool = False) -> None:
        super().__init__()
        self.name, self.key, self.factor, self.broken_key = name, key, factor, broken_key
        self.restored = 0

    def restore(self, sensor: torch.Tensor) -> torch.Tensor:
        self.restored += sensor.shape[0]
        return sensor * self.factor

    def restoration_key(self) -> str | None:
        if self.broken_key:
            raise RuntimeError("planted")
        return self.key


class _MeanReader(attacks.Reader):
    """One read per image, its confidence the image's mean: its outcome depends on the pixels it was given."""

    name = "mean-reader"
    threat_model = attacks.ThreatModel.SENSOR_ACCESS
    calls = 0

    def read(self, images, hints=None):
        _MeanReader.calls += len(images)
        return [[attacks.PlateRead("AB123CD", (0.0, 0.0, 8.0, 4.0), float(im.mean()))] for im in images]


def _evaluate(restorers: list[attacks.Restorer]) -> Attacked:
    cfg, target, rows, _, _ = small_target()
    out = Attacked()
    readers = [ReadyReader(_MeanReader(), None, {"name": "mean-reader"})]
    run_restorers(target, list(restorers), {}, cfg, rows, out, readers)
    out.finish()
    return out


def _rows(out: Attacked, attack: str) -> list[dict]:
    rows = [r.to_json() for r in out.rows if r.attack in (attack, f"{attack}>mean-reader")]
    for r in rows:  # what may differ between two restorations of the same images: the clock, the note
        r["metrics"] = {k: v for k, v in r["metrics"].items() if not k.endswith("_per_s") and k != "fit_s"}
        r["notes"] = {k: v for k, v in r["notes"].items() if k != RESTORED_AS}
    return rows


@pytest.mark.slow
def test_a_twin_is_restored_once_and_scored_as_its_own_restoration_would_be():
    first, twin = _Keyed("first", "k"), _Keyed("twin", "k")
    _MeanReader.calls = 0
    shared = _evaluate([first, twin])
    assert first.restored == 3 + 2 and twin.restored == 0  # 3 scenes and 2 windows, once
    assert _MeanReader.calls == 2
    twin_rows = [r for r in shared.rows if r.attack in ("twin", "twin>mean-reader")]
    assert len(twin_rows) == 2 and twin_rows[0].notes[RESTORED_AS] == "first"
    # The reference: the same two restorers claiming nothing, each restored on its own.
    alone_first, alone_twin = _Keyed("first", None), _Keyed("twin", None)
    alone = _evaluate([alone_first, alone_twin])
    assert alone_twin.restored == 5 and RESTORED_AS not in alone.rows[1].notes
    assert _rows(shared, "twin") == _rows(alone, "twin") and _rows(shared, "first") == _rows(alone, "first")
    assert set(shared.restored_plates["twin"]) == set(alone.restored_plates["twin"])


@pytest.mark.slow
def test_other_keys_or_a_key_that_raises_restore_on_their_own():
    a, b, broken = _Keyed("a", "k1"), _Keyed("b", "k2", factor=0.5), _Keyed("c", "k1", broken_key=True)
    out = _evaluate([a, b, broken])
    assert (a.restored, b.restored, broken.restored) == (5, 5, 5)
    assert all(RESTORED_AS not in r.notes for r in out.rows)
    means = {r.attack: r.metrics["psnr_db"] for r in out.rows if r.kind == "restorer"}
    assert means["a"] == means["c"] != means["b"]
