"""The probe of a reader that walks the runner's stack to the scenes' plate texts: in the runner's process
it reads every plate of the ideal lens (the genie's ceiling allows that there, so the ceiling guard cannot
tell it from a strong reader); isolated (the default) it finds nothing to read,
while its rows, chains and the restorer beside it are scored as usual. Isolation is the default; the
runner's process is asked for with ``isolate=False`` (``--no-isolate``)."""

from __future__ import annotations

import textwrap

import pytest

import benchmark
from benchmark.results.schema import read_results

pytestmark = pytest.mark.slow  # two smoke runs of ideal; the isolated one starts attacker processes

PEEKER = textwrap.dedent('''
    import inspect
    from attacks import PlateRead, Reader, Restorer, ThreatModel


    class StackPeeker(Reader):
        name = "stack-peeker"; threat_model = ThreatModel.SENSOR_ACCESS

        def read(self, images, hints=None):
            frame = inspect.currentframe()
            while frame is not None and "chunks" not in frame.f_locals:
                frame = frame.f_back
            chunk = frame.f_locals["chunks"][-1] if frame is not None else [None] * len(images)
            return [[PlateRead(p.text, p.box_xyxy, 1.0) for p in (scene.plates if scene else [])] for scene in chunk]


    class Keep(Restorer):
        name = "keep"; threat_model = ThreatModel.SENSOR_ACCESS

        def restore(self, sensor):
            return sensor
''')


@pytest.fixture(scope="module")
def runs(tmp_path_factory):
    root = tmp_path_factory.mktemp("isolated")
    (root / "peek.py").write_text(PEEKER)
    attackers = [f"{root / 'peek.py'}:StackPeeker", f"{root / 'peek.py'}:Keep"]
    out = {}
    with pytest.MonkeyPatch.context() as mp:
        mp.setenv("PLB_CACHE", str(root / "cache"))
        for isolate in (False, True):
            benchmark.run(lenses=["ideal"], attacks=attackers, profile="smoke", out=root / str(isolate), isolate=isolate)
            out[isolate] = read_results(root / str(isolate) / "results.json")
    return out


def _rows(results):
    return {(r.kind, r.attack): r for r in results.rows if r.lens == "ideal"}


def test_in_the_runners_process_the_peeker_reads_every_plate_of_the_ideal_lens(runs):
    rows = _rows(runs[False])
    assert rows[("reader", "stack-peeker")].metrics["plate_acc"] == 1.0
    assert "isolated" not in runs[False].meta  # nothing ran isolated


def test_isolated_it_reads_nothing_and_every_row_is_scored_as_usual(runs):
    rows, plain = _rows(runs[True]), _rows(runs[False])
    assert runs[True].meta["isolated"] == ["keep", "stack-peeker"]
    assert set(rows) == set(plain)
    for key in (("reader", "stack-peeker"), ("chain", "keep>stack-peeker")):
        assert rows[key].ok and rows[key].metrics["plate_acc"] == 0.0
        assert rows[key].metrics["n_plates"] == plain[key].metrics["n_plates"] > 0
    assert rows[("restorer", "keep")].metrics["psnr_db"] == pytest.approx(plain[("restorer", "keep")].metrics["psnr_db"])
