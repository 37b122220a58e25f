"""Attackers' outputs are checked before scoring: nothing non-finite, mis-shaped or out of range is scored."""

import math
import re

import pytest
import torch

import attacks
from benchmark.runner.evaluation import OutputError, attempt, check_reads, check_restored, read_plates, restoration_metrics
from benchmark.scenes import load_scenes
from benchmark.results.metrics import finite_mean
from benchmark.results.schema import RowError

SENSOR = torch.rand(2, 3, 24, 32, generator=torch.Generator().manual_seed(0))


@pytest.mark.parametrize("out, text", [
    (SENSOR[..., :-1], "shape (2, 3, 24, 31)"),
    (torch.full_like(SENSOR, math.nan), "non-finite"),
    (torch.full_like(SENSOR, math.inf), "non-finite"),
    (SENSOR * 3, "values in"),
    ((SENSOR * 255).to(torch.uint8), "dtype"),
    (SENSOR.numpy(), "not a tensor"),
])
def test_bad_restorer_outputs_are_refused_naming_the_attacker(out, text):
    with pytest.raises(OutputError, match=re.escape(text)) as info:
        check_restored("median3", out, SENSOR)
    assert "median3" in str(info.value)


def test_a_good_output_passes_unchanged():
    assert torch.equal(check_restored("x", SENSOR, SENSOR), SENSOR)


@pytest.mark.parametrize("reads, text", [
    ([[]], "a list of 1 for 2"),
    ([[], ["ABC"]], "PlateRead"),
    ({"a": 1}, "dict"),
])
def test_bad_reader_outputs_are_refused(reads, text):
    with pytest.raises(OutputError, match=re.escape(text)):
        check_reads("echo", reads, 2)


def test_good_reads_pass():
    reads = [[], [attacks.PlateRead("AB12", (0.0, 0.0, 4.0, 2.0), 0.9)]]
    assert check_reads("echo", reads, 2) is reads


class _BatchCount(attacks.Reader):
    """Reads nothing; its read_batches drops the last batch when `drop` is set."""

    name = "batch-count"
    threat_model = attacks.ThreatModel.SENSOR_ACCESS

    def __init__(self, drop: bool) -> None:
        self.drop = drop

    def read(self, images, hints=None):
        return [[] for _ in images]

    def read_batches(self, batches):
        out = super().read_batches(batches)
        return out[:-1] if self.drop else out


class _StopsEarly(_BatchCount):
    """Reads only the first batch it is given, and returns one list for it."""

    def read_batches(self, batches):
        return [self.read(*next(iter(batches)))]


def test_a_reader_is_given_every_batch_in_one_call_and_a_missing_batch_is_refused():
    scenes = load_scenes("synthetic", "val", 3, (32, 64), 0)
    images = torch.rand(3, 3, 32, 64)
    outcomes, timing, reads = read_plates(_BatchCount(drop=False), images, scenes, 2, "cpu")
    assert reads == [[], [], []] and timing["n_images"] == 3
    with pytest.raises(OutputError, match=re.escape("batch-count.read_batches returned 1 batches for 2")):
        read_plates(_BatchCount(drop=True), images, scenes, 2, "cpu")
    with pytest.raises(OutputError, match=re.escape("batch-count.read_batches took 1 batch(es) and left the rest unread")):
        read_plates(_StopsEarly(drop=False), images, scenes, 2, "cpu")


def test_an_exception_becomes_the_error_of_a_failed_row():
    def boom():
        raise RuntimeError("exploded")

    error = attempt("x", "fit", boom)
    assert error == RowError("x", "fit", "RuntimeError: exploded")
    assert attempt("x", "fit", lambda: 3) == 3


def test_an_exact_copy_has_no_psnr_mean_rather_than_inf():
    metrics, per_image = restoration_metrics(SENSOR, SENSOR)
    assert "psnr_db" not in metrics and metrics["ssim"] == pytest.approx(1.0)
    assert per_image["psnr_db"] == [math.inf, math.inf]


def test_finite_mean_never_turns_nan_into_a_score():
    with pytest.raises(ValueError, match="NaN"):
        finite_mean(torch.tensor([20.0, math.nan]))
    assert finite_mean(torch.tensor([20.0, 30.0])) == 25.0


def _read(text, score, box=(10.0, 10.0, 42.0, 18.0)):
    return attacks.PlateRead(text, box, score)


@pytest.mark.parametrize("reads, text", [
    ([_read("AB123CD", 0.5)] * 65, "65 reads of one image, more than MAX_READS_PER_IMAGE = 64"),
    ([_read("A" * 1_000_000, 0.5)], "a read's text is 1000000 characters; at most MAX_READ_CHARS = 32"),
    ([_read("AB123CD", 1.5)], "a read's score is 1.5; scores lie in [0, 1]"),
    ([_read("AB123CD", float("nan"))], "a read's score is nan"),
    ([_read("AB123CD", 0.5, (0.0, 0.0, float("inf"), 1.0))], "a read's box is (0.0, 0.0, inf, 1.0); boxes are four finite"),
])
def test_reads_past_the_limits_fail_the_row_naming_the_limit(reads, text):
    with pytest.raises(OutputError, match=re.escape(f"echo.read returned {text}")):
        check_reads("echo", [reads], 1)


def _scene():
    import numpy as np

    from benchmark.scenes.records import Plate, Scene
    plate = Plate("AB123CD", (10.0, 10.0, 42.0, 18.0), 0, 1.0)
    return Scene(np.zeros((32, 64, 3), np.float32), np.zeros((32, 64), np.uint8), [plate], [], 0, "s")


def test_one_read_per_plate_counts_the_readers_best_scored_one():
    from benchmark.results.plate_scoring import score_scene
    scene = _scene()
    # The right text at a lower score than a wrong one does not count; at the higher score it does.
    (hedged,) = score_scene([_read("XX999XX", 0.9), _read("AB123CD", 0.2)], scene)
    assert not hedged.correct and hedged.read == "XX999XX" and hedged.cer == 1.0
    (trusted,) = score_scene([_read("XX999XX", 0.2), _read("AB123CD", 0.9)], scene)
    assert trusted.correct and trusted.cer == 0.0
    # Of equal scores the first read counts, whatever the truth.
    (first,) = score_scene([_read("XX999XX", 0.5), _read("AB123CD", 0.5)], scene)
    assert first.read == "XX999XX"


def test_many_guesses_score_as_the_one_the_reader_trusts_most():
    import random

    from benchmark.results.plate_scoring import levenshtein, score_scene
    rng = random.Random(0)
    alphabet = "ABCDEFGHIJKLMNOPQRSTUVWXYZ0123456789"
    guesses = ["".join(rng.choice(alphabet) for _ in range(7)) for _ in range(63)]
    scene = _scene()
    reads = [_read(g, 0.01 + 0.5 * rng.random()) for g in guesses] + [_read("AB123CD", 0.0)]
    (many,) = score_scene(reads, scene)
    top = max(reads, key=lambda r: r.score)
    (one,) = score_scene([top], scene)
    assert many == one and many.cer == levenshtein(top.text, "AB123CD") / 7


def test_a_reader_is_handed_only_the_hints_it_declares():
    import numpy as np

    from benchmark.scenes.records import Plate, Scene, Vehicle

    class Recorder(attacks.Reader):
        name = "recorder"
        threat_model = attacks.ThreatModel.SENSOR_ACCESS

        def __init__(self):
            self.seen = []

        def read(self, images, hints=None):
            self.seen.append(hints)
            return [[] for _ in images]

    class PlateOracle(Recorder):
        name = "plate-oracle"
        hints = frozenset({"plate_boxes"})

    scene = Scene(np.zeros((16, 32, 3), np.float32), np.zeros((16, 32), np.uint8),
                  [Plate("AB123CD", (2.0, 2.0, 12.0, 6.0), 0, 1.0)], [Vehicle(13, (0.0, 0.0, 20.0, 10.0))], 0, "s")
    images = torch.zeros(1, 3, 16, 32)
    blind, oracle = Recorder(), PlateOracle()
    for reader in (blind, oracle):
        read_plates(reader, images, [scene], 1, "cpu", segment=lambda x: x[:, 0].long())
    (given,) = blind.seen
    assert given.vehicle_boxes is None and given.segment is None and given.plate_boxes is None
    (given,) = oracle.seen
    assert given.plate_boxes == [[(2.0, 2.0, 12.0, 6.0)]] and given.vehicle_boxes is None and given.segment is None
    assert blind.describe()["hints"] == [] and oracle.describe()["hints"] == ["plate_boxes"]


def test_a_hint_that_is_no_readhints_field_is_refused_at_class_creation():
    with pytest.raises(TypeError, match=r"hints names \['answers'\], which are not ReadHints fields; valid: "
                                        r"\['plate_boxes', 'segment', 'vehicle_boxes'\]"):
        class Greedy(attacks.Reader):
            name = "greedy"
            threat_model = attacks.ThreatModel.SENSOR_ACCESS
            hints = frozenset({"answers"})

            def read(self, images, hints=None):
                return [[] for _ in images]


def test_a_long_error_is_cut_in_the_row_and_kept_whole_in_the_log(caplog):
    dump = "Could not run 'aten::add' with arguments from the 'SparseCPU' backend. " + "backend list " * 400

    def fails():
        raise NotImplementedError(dump)

    with caplog.at_level("WARNING"):
        error = attempt("sparse", "restore", fails)
    assert isinstance(error, RowError) and len(error.message) < 600
    assert error.message.startswith("NotImplementedError: Could not run 'aten::add'")
    assert error.message.endswith(f"({len('NotImplementedError: ' + dump) - 500} more characters in the log)")
    assert dump.strip() in caplog.text
