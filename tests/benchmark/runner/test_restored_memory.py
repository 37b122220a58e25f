"""What `run_restorers` keeps of each restorer's scenes when plates are read on windows: one scene
for the sample picture, in storage of its own. A slice of the batch would keep all 64 restored scenes
of every restorer alive (about 400 MB each on quick): a fresh quick run was killed for memory at
24 GB before this was a copy."""

from __future__ import annotations

import gc
import weakref

import pytest
import torch

import attacks
from benchmark.runner.evaluation import Attacked, ReadyReader, gallery_windows, run_restorers
from window_target import small_target  # tests/window_target.py


class _Blind(attacks.Reader):
    """Reads nothing: a chain that makes the evaluation restore the windows (it restores none no chain reads)."""
    name = "blind"
    threat_model = attacks.ThreatModel.SENSOR_ACCESS

    def read(self, images, hints=None):
        return [[] for _ in range(images.shape[0])]


READERS = [ReadyReader(_Blind(), None, {"name": "blind"})]


@pytest.mark.slow
def test_the_kept_scene_does_not_hold_the_restored_batch():
    cfg, target, rows, sensor, windows = small_target()
    plates = target.plates
    out = Attacked()
    restorers = [attacks.load("raw")]
    gone = weakref.ref(restorers[0])
    run_restorers(target, restorers, {}, cfg, rows, out, READERS)
    # Consumed: nothing of the evaluation holds a scored restorer (or its inference session) any more.
    assert restorers == [] and gone() is None
    kept = out.restored["raw"]
    assert kept.shape == (1, *sensor.shape[1:])
    assert kept.untyped_storage().nbytes() == kept.numel() * kept.element_size()
    # Of the windows only the plate gallery's are kept (the readers read them all before they go).
    kept_windows = out.restored_plates["raw"]
    assert list(kept_windows) == gallery_windows(plates) and len(kept_windows) < len(windows)
    for i, window in kept_windows.items():
        assert window.shape == windows[i].shape


def test_restoration_metrics_score_in_chunks_with_the_one_batch_values(monkeypatch):
    import benchmark.runner.evaluation as evaluation
    from benchmark.results.metrics import psnr, ssim

    g = torch.Generator().manual_seed(0)
    sharp = torch.rand(19, 3, 24, 40, generator=g)
    restored = (sharp + 0.05 * torch.randn(19, 3, 24, 40, generator=g)).clamp(0, 1)
    sizes = []
    monkeypatch.setattr(evaluation, "ssim", lambda x, ref: sizes.append(x.shape[0]) or ssim(x, ref))
    metrics, per_image = evaluation.restoration_metrics(restored, sharp)
    assert max(sizes) <= evaluation.METRIC_CHUNK and sum(sizes) == 19
    torch.testing.assert_close(torch.tensor(per_image["ssim"], dtype=torch.float64), ssim(restored, sharp),
                               rtol=0, atol=1e-12)
    torch.testing.assert_close(torch.tensor(per_image["psnr_db"], dtype=torch.float64), psnr(restored, sharp).double(),
                               rtol=0, atol=1e-9)
    assert metrics["n_images"] == 19.0


class _Recording(attacks.Restorer):
    name = "recording"

    def __init__(self) -> None:
        super().__init__()
        self.batches: list[int] = []

    def restore(self, sensor: torch.Tensor) -> torch.Tensor:
        self.batches.append(sensor.shape[0])
        return sensor.flip(-1)


def test_whole_frames_are_restored_a_pixel_budget_at_a_time_in_order():
    """Quick frames (512 x 1024) go two per call whatever the profile's batch; small frames keep it;
    the restorations come back complete and in order."""
    from benchmark.runner.evaluation import RESTORE_PIXELS_PER_BATCH, frames_per_batch, restore_all
    big = torch.rand(5, 3, 512, 1024, generator=torch.Generator().manual_seed(0))
    assert frames_per_batch(big, 8) == RESTORE_PIXELS_PER_BATCH // (512 * 1024) == 2
    assert frames_per_batch(torch.rand(5, 3, 128, 256), 4) == 4
    assert frames_per_batch(torch.rand(1, 3, 2048, 4096), 8) == 1
    restorer = _Recording()
    out = restore_all(restorer, big, 8, "cpu")
    assert restorer.batches == [2, 2, 1]
    torch.testing.assert_close(out, big.flip(-1), rtol=0, atol=0)


def test_plate_windows_are_restored_a_pixel_budget_at_a_time_in_order():
    """Windows of one shape go at most the profile's batch and RESTORE_PIXELS_PER_BATCH pixels per call;
    the restorations come back complete and in order."""
    from benchmark.runner.evaluation import RESTORE_PIXELS_PER_BATCH, restore_windows
    g = torch.Generator().manual_seed(0)
    windows = [torch.rand(3, 512, 512, generator=g) for _ in range(5)] + [torch.rand(3, 64, 64, generator=g)
                                                                          for _ in range(3)]
    assert RESTORE_PIXELS_PER_BATCH // (512 * 512) == 4
    restorer = _Recording()
    out = restore_windows(restorer, windows, 2, "cpu")
    assert restorer.batches == [2, 2, 1, 2, 1]
    restorer = _Recording()
    out = restore_windows(restorer, windows, 8, "cpu")
    assert restorer.batches == [4, 1, 3]
    assert len(out) == len(windows)
    for got, want in zip(out, windows):
        torch.testing.assert_close(got, want.flip(-1), rtol=0, atol=0)


class _FrameCounter(attacks.Restorer):
    """Flips its input; when given the plate windows, counts the live tensors shaped like the whole
    restored frame batch."""
    name = "frame-counter"
    threat_model = attacks.ThreatModel.SENSOR_ACCESS

    def __init__(self, frames_shape: tuple[int, ...]) -> None:
        super().__init__()
        self.frames_shape = frames_shape
        self.alive_during_windows: list[int] = []

    def restore(self, sensor: torch.Tensor) -> torch.Tensor:
        if sensor.shape[-2:] != self.frames_shape[-2:]:
            gc.collect()
            self.alive_during_windows.append(sum(
                1 for o in gc.get_objects() if isinstance(o, torch.Tensor) and tuple(o.shape) == self.frames_shape))
        return sensor.flip(-1)


@pytest.mark.slow
def test_scored_frames_are_gone_before_the_windows_are_restored():
    """A restorer's 64 restored frames (about 400 MB on quick) are scored first and dropped (but the
    sample picture's one) before its plate windows are restored and read."""
    cfg, target, rows, sensor, _ = small_target(own_copies=True)
    counter = _FrameCounter(tuple(sensor.shape))
    out = Attacked()
    run_restorers(target, [counter], {}, cfg, rows, out, READERS)
    assert counter.alive_during_windows, "the windows were restored"
    # alive: the local `sensor`, the target's sensor and sharp scenes; not the restored batch
    assert set(counter.alive_during_windows) == {3}
    assert out.rows[-1].metrics["n_images"] == 3 and out.restored["frame-counter"].shape[0] == 1
