"""A reader above the ideal observer's ceiling is a failed row, never a result, and a run holding one
is not published: the reader of this test reads the answers off the runner's stack, as a dishonest
plugin could, and reads every plate of defocus, where the ceiling allows at most about a fifth of
the 8-12 px ones."""

from __future__ import annotations

import textwrap

import pytest

pytestmark = pytest.mark.slow  # a smoke run of defocus

PEEKER = textwrap.dedent('''
    import inspect
    from typing import ClassVar
    from attacks import PlateRead, Reader, ThreatModel


    class StackPeeker(Reader):
        name: ClassVar[str] = "stack-peeker"
        threat_model: ClassVar[ThreatModel] = ThreatModel.SENSOR_ACCESS

        def read(self, images, hints=None):
            frame = inspect.currentframe()
            while frame is not None and "chunks" not in frame.f_locals:
                frame = frame.f_back
            chunk = frame.f_locals["chunks"][-1] if frame is not None else []
            return [[PlateRead(p.text, p.box_xyxy, 1.0) for p in scene.plates] for scene in chunk]
''')


@pytest.fixture(scope="module")
def peeked(tmp_path_factory):
    import benchmark
    root = tmp_path_factory.mktemp("peek")
    (root / "peek.py").write_text(PEEKER)
    with pytest.MonkeyPatch.context() as mp:
        mp.setenv("PLB_CACHE", str(root / "cache"))
        # in the runner's process (isolated, the default, it finds no answers to read: tests/benchmark/runner/sandbox)
        results = benchmark.run(lenses=["defocus"], attacks=[f"{root / 'peek.py'}:StackPeeker"], profile="smoke",
                                out=root / "out", isolate=False)
    return root, results


def test_a_reader_above_the_ceiling_is_a_failed_row_naming_the_violation(peeked):
    from benchmark.results.schema import read_results
    root, results = peeked
    (row,) = [r for r in read_results(root / "out" / "results.json").rows if r.lens == "defocus"
              and r.attack == "stack-peeker"]
    assert not row.ok and not row.metrics and row.error.stage == "score"
    assert row.error.message.startswith("CEILING VIOLATION: reader 'stack-peeker' on lens 'defocus' reads 100.0 %")
    assert row in results.failed


def test_a_run_with_a_reader_above_the_ceiling_is_not_published(peeked, tmp_path):
    from benchmark.publish import leaderboard
    from benchmark.store.profiles import get_profile
    root, results = peeked
    board = tmp_path / "board"
    with pytest.raises(ValueError, match=r"refusing to publish: 1 row\(s\) read above the ideal observer's ceiling, "
                                         r"e\.g\. defocus/stack-peeker seed 0: CEILING VIOLATION"):
        leaderboard.publish_run(results.rows, get_profile("smoke").to_dict(), results.output.lens_info, root / "out",
                                directory=board, settings=results.settings)
    assert not board.exists()
