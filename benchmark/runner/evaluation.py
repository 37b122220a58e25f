"""Attack one lens: restore with every restorer, read with every reader on the sensor image and on
each restorer's output, and score everything the same way.

An attacker that raises (anything but Ctrl-C: `benchmark.runner.isolation.attempt`), or returns the
wrong shape, dtype, range or non-finite values, gives a failed row (attacker, stage, message) and
never a metric; the other attackers' rows are complete. Every attacker is handed its own copies of
its inputs (`isolation.private`, `isolation.own_context`), so none can change another's score.
"""

from __future__ import annotations

import logging
import math
import os
import time
from collections.abc import Callable, Iterator, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import torch
from tqdm.auto import tqdm

import attacks
from benchmark.runner.isolation import attempt, describe, own_context, private
from benchmark.runner.intervals import plate_intervals, scene_intervals
from benchmark.results.metrics import psnr, ssim
from benchmark.runner.diagnostics.native_memory import release_free_memory
from benchmark.results.plate_scoring import PlateOutcome, check_read_limits, pooled, readable, score_scene, summarise
from benchmark.runner.rows import RowBuilder, plate_units, scene_units
from benchmark.runner.config import RunConfig
from benchmark.scenes import Scene
from benchmark.results.schema import FIT_STILL_RISING, LEARNS, Row, RowError, chain_name
from benchmark.runner.sensing import batches

log = logging.getLogger(__name__)

# How far outside [0, 1] a restored image may stray (float rounding of a clamp-free network).
RANGE_TOLERANCE = 1e-4


class OutputError(ValueError):
    """An attacker returned something other than what its contract promises."""


def check_restored(name: str, out: object, sensor: torch.Tensor) -> torch.Tensor:
    """`out` if it is a finite float tensor shaped like `sensor` with values in [0, 1], else OutputError."""
    if not isinstance(out, torch.Tensor):
        raise OutputError(f"{name}.restore returned {type(out).__name__}, not a tensor")
    if out.shape != sensor.shape:
        raise OutputError(f"{name}.restore returned shape {tuple(out.shape)} for input {tuple(sensor.shape)}")
    if not out.is_floating_point():
        raise OutputError(f"{name}.restore returned dtype {out.dtype}; expected a float tensor")
    # One pass: a NaN anywhere makes aminmax NaN, an inf shows as the min or max.
    low, high = (float(v) for v in torch.aminmax(out))
    if not (math.isfinite(low) and math.isfinite(high)):
        bad = int((~torch.isfinite(out)).sum())
        raise OutputError(f"{name}.restore returned {bad} non-finite value(s) (NaN/inf)")
    if low < -RANGE_TOLERANCE or high > 1 + RANGE_TOLERANCE:
        raise OutputError(f"{name}.restore returned values in [{low:.4g}, {high:.4g}]; expected [0, 1]")
    # clamp makes a new tensor: what is kept is out of reach of the attacker that returned `out`.
    return out.float().clamp(0, 1)


def check_reads(name: str, reads: object, n_images: int) -> list[list[attacks.PlateRead]]:
    """`reads` if it is one list of PlateRead per image, else OutputError."""
    if not isinstance(reads, list) or len(reads) != n_images:
        got = f"a list of {len(reads)}" if isinstance(reads, list) else type(reads).__name__
        raise OutputError(f"{name}.read returned {got} for {n_images} image(s); expected one list per image")
    for per_image in reads:
        if not isinstance(per_image, list) or not all(isinstance(r, attacks.PlateRead) for r in per_image):
            raise OutputError(f"{name}.read must return lists of attacks.PlateRead, got {per_image!r:.120}")
        broken = check_read_limits(per_image)
        if broken is not None:
            raise OutputError(f"{name}.read returned {broken}")
    return reads


# Whole frames go to a restorer a few at a time: a network's activations grow with the pixels of its
# batch. Two quick frames a call raise the resident peak far less than eight, at the same speed, and
# plate windows (256 x 256 to 512 x 704 in quick) are bounded the same way (docs/history.md).
RESTORE_PIXELS_PER_BATCH = 2 * 512 * 1024


def frames_per_batch(images: torch.Tensor, batch_size: int, max_pixels: int = RESTORE_PIXELS_PER_BATCH) -> int:
    """How many images shaped like ``images`` (...,H,W) one call takes: ``batch_size``, fewer where
    that would pass ``max_pixels`` pixels, at least one."""
    return max(1, min(batch_size, max_pixels // (int(images.shape[-2]) * int(images.shape[-1]))))


def restore_all(attacker: attacks.Restorer, sensor: torch.Tensor, batch_size: int, device: str) -> torch.Tensor:
    """The attacker's restorations of every sensor image (N,3,H,W), checked, on the CPU, at most
    ``batch_size`` images (and ``RESTORE_PIXELS_PER_BATCH`` pixels) per call."""
    outs = []
    with torch.no_grad():
        for b in batches(sensor, frames_per_batch(sensor, batch_size)):
            outs.append(check_restored(attacker.name, attacker.restore(private(b, device)), b).cpu())
    return torch.cat(outs)


def shape_batches(images: torch.Tensor | Sequence[torch.Tensor], size: int, max_pixels: int | None = None
                  ) -> Iterator[tuple[int, torch.Tensor]]:
    """(index of the first image, batch (B,3,H,W)) over `images`: a tensor (N,3,H,W) in slices of
    `size`, or a sequence of (3,h,w) tensors in runs of consecutive equal shapes, at most `size` each
    and, given `max_pixels`, at most that many pixels (at least one image)."""
    if isinstance(images, torch.Tensor):
        for start in range(0, images.shape[0], size):
            yield start, images[start:start + size]
        return
    start = 0
    while start < len(images):
        end = start + 1
        limit = size if max_pixels is None else frames_per_batch(images[start], size, max_pixels)
        while end < len(images) and end - start < limit and images[end].shape == images[start].shape:
            end += 1
        yield start, torch.stack(list(images[start:end]))
        start = end


def restore_windows(attacker: attacks.Restorer, windows: Sequence[torch.Tensor], batch_size: int, device: str
                    ) -> list[torch.Tensor]:
    """The attacker's restorations (3,h,w) of sensor windows of several sizes, checked, on the CPU, at
    most ``batch_size`` windows (and ``RESTORE_PIXELS_PER_BATCH`` pixels) per call."""
    outs: list[torch.Tensor] = []
    with torch.no_grad():
        for _, b in shape_batches(windows, batch_size, RESTORE_PIXELS_PER_BATCH):
            outs.extend(check_restored(attacker.name, attacker.restore(private(b, device)), b).cpu())
    return outs


METRIC_CHUNK = 8


def restoration_metrics(restored: torch.Tensor, sharp: torch.Tensor) -> tuple[dict[str, float], dict[str, list[float]]]:
    """Mean PSNR (dB) and SSIM of restored vs sharp (N,3,H,W), n_images; and the per-image values.

    A per-image PSNR is infinite only for an exact copy; the mean is then left out, never inf.
    Scored METRIC_CHUNK images at a time: SSIM's float64 intermediates for 64 quick scenes at once
    are about 10 GB.
    """
    per_image: dict[str, list[float]] = {"psnr_db": [], "ssim": []}
    for start in range(0, sharp.shape[0], METRIC_CHUNK):
        x, ref = restored[start:start + METRIC_CHUNK], sharp[start:start + METRIC_CHUNK]
        per_image["psnr_db"] += psnr(x, ref).tolist()
        per_image["ssim"] += ssim(x, ref).tolist()
    metrics = {"n_images": float(sharp.shape[0])}
    for name, values in per_image.items():
        if all(torch.isfinite(torch.tensor(values))):
            metrics[name] = float(torch.tensor(values, dtype=torch.float64).mean())
    return metrics, per_image


def read_plates(reader: attacks.Reader, images: torch.Tensor | Sequence[torch.Tensor], scenes: list[Scene],
                batch_size: int, device: str, segment: Callable[[torch.Tensor], torch.Tensor] | None = None
                ) -> tuple[list[PlateOutcome], dict[str, float], list[list[attacks.PlateRead]]]:
    """Run a reader over images (N,3,H,W), or plate windows (3,h,w) of several sizes, batch-wise and
    score it against the scenes' plates (one scene record per image).

    Returns the per-plate outcomes, the timing (``images_per_s``, and ``<stage>_s_per_image`` for
    readers whose ``stage_seconds`` grew, like lpdr), n_images and the reads per image.
    """
    outcomes: list[PlateOutcome] = []
    all_reads: list[list[attacks.PlateRead]] = []
    stages_before = dict(reader.stage_seconds)
    t0 = time.perf_counter()
    chunks: list[list[Scene]] = []

    def inputs() -> Iterator[tuple[torch.Tensor, attacks.ReadHints]]:
        for start, batch in shape_batches(images, batch_size):
            chunk = scenes[start:start + batch.shape[0]]
            chunks.append(chunk)
            given = reader.hints  # only the hints the reader declares (attacks.base.Reader.hints)
            yield private(batch, device), attacks.ReadHints(
                vehicle_boxes=[[v.box_xyxy for v in s.vehicles] for s in chunk] if "vehicle_boxes" in given else None,
                segment=segment if "segment" in given else None,
                plate_boxes=[[p.box_xyxy for p in s.plates] for s in chunk] if "plate_boxes" in given else None)

    # One call for every batch: a reader may share work across them (lpdr recognises all crops together).
    batches = inputs()
    with torch.no_grad():
        per_batch = reader.read_batches(batches)
    if next(batches, None) is not None:  # a batch never read would silently drop its plates from the score
        raise OutputError(f"{reader.name}.read_batches took {len(chunks) - 1} batch(es) and left the rest "
                          "unread; it must read every batch it is given")
    if not isinstance(per_batch, list) or len(per_batch) != len(chunks):
        got = f"{len(per_batch)} batches" if isinstance(per_batch, list) else type(per_batch).__name__
        raise OutputError(f"{reader.name}.read_batches returned {got} for {len(chunks)}; expected one list per batch")
    for batch_reads, chunk in zip(per_batch, chunks):
        reads = check_reads(reader.name, batch_reads, len(chunk))
        for r, scene in zip(reads, chunk):
            outcomes.extend(score_scene(r, scene))
        all_reads.extend(reads)
    n_images = len(images)
    timing = {"images_per_s": n_images / (time.perf_counter() - t0), "n_images": float(n_images)}
    for stage, seconds in reader.stage_seconds.items():
        timing[f"{stage}_s_per_image"] = (seconds - stages_before.get(stage, 0.0)) / n_images
    return outcomes, timing, all_reads


@dataclass
class PlateSet:
    """The plate images of one lens and seed: one window per scored plate (benchmark.scenes.windows).

    ``scenes`` are the windows as scene records (each holds its one scored plate, in window
    pixels), ``sharp`` and ``sensor`` their images (3,h,w) in [0,1]; ``n_frames`` the frames
    they were cut from."""

    scenes: list[Scene]
    sharp: list[torch.Tensor]
    sensor: list[torch.Tensor]
    n_frames: int


@dataclass
class Target:
    """What the attackers of one lens and seed see: sharp scenes, sensor images and the fit context."""

    lens_name: str
    scenes: list[Scene]
    sharp: torch.Tensor                 # (N,3,H,W) in [0,1]
    sensor: torch.Tensor                # (N,3,H,W) in [0,1]; the sharp scenes themselves for lens `sharp`
    ctx: attacks.FitContext
    segment_sensor: Callable[[torch.Tensor], torch.Tensor] | None   # lens's own net on sensor images
    segment_restored: Callable[[torch.Tensor], torch.Tensor] | None  # clean net on restored images
    plates: PlateSet | None = None      # where plates are read; None: on the scenes themselves


ReadResult = tuple[list[PlateOutcome], dict[str, float], list[list[attacks.PlateRead]]]
"""What ``read_plates`` returns: per-plate outcomes, timing, the reads."""


@dataclass
class Restored:
    """What a restorer's output gave in this evaluation, kept (small) so that a later restorer with the same
    ``restoration_key`` is scored from it without restoring again: the scene metrics and each reader's reads
    of its plate windows."""

    name: str
    metrics: dict[str, float]
    per_image: dict[str, list[float]]
    reads: dict[str, ReadResult] = field(default_factory=dict)  # reader name -> its read of the windows


@dataclass
class Attacked:
    """Rows, per-plate records and restored images of one lens and seed."""

    rows: list[Row] = field(default_factory=list)
    plates: list[dict] = field(default_factory=list)
    restored: dict[str, torch.Tensor] = field(default_factory=dict)
    reads: dict[str, list[list[attacks.PlateRead]]] = field(default_factory=dict)
    described: dict[str, dict] = field(default_factory=dict)  # restorer name -> describe()
    references: set[str] = field(default_factory=set)          # restorers marked `reference`
    threat_models: dict[str, attacks.ThreatModel] = field(default_factory=dict)  # restorer name -> its own
    learns: dict[str, bool] = field(default_factory=dict)  # restorer name -> its Attack.learns
    # restorer -> {window index: restored window}, only the windows the plate gallery shows
    # (gallery_windows): the others are read as soon as they are restored, then dropped.
    restored_plates: dict[str, dict[int, torch.Tensor]] = field(default_factory=dict)
    # Reader rows and plate records, per reader in chain order (sensor first, then each restorer),
    # kept apart while restorers and readers interleave; `finish` appends them to rows / plates.
    reader_rows: dict[str, list[Row]] = field(default_factory=dict)
    reader_plates: dict[str, list[dict]] = field(default_factory=dict)
    by_key: dict[str, Restored] = field(default_factory=dict)  # restoration_key -> the first restorer of it

    def finish(self) -> None:
        """Move the reader rows and plate records after the restorer rows, reader by reader."""
        for name in list(self.reader_rows):
            self.rows.extend(self.reader_rows.pop(name))
            self.plates.extend(self.reader_plates.pop(name, []))


def run_restorers(target: Target, restorers: list[attacks.Restorer], fitted: dict[str, dict], cfg: RunConfig,
                  rows: RowBuilder, out: Attacked, readers: Sequence[ReadyReader] = ()) -> None:
    """Restore with each restorer (fitted by its own task: `fitted[name]` = that task's meta), score
    it, and read its output with each of `readers` (the chains) before the next restorer, so that
    only one restorer's plate windows are in memory at a time.

    `restorers` is consumed: each restorer is dropped from it once scored, so that its network and
    inference session (about 1 GB for a quick NAFNet in ONNX Runtime) go, and the memory they held
    goes back to the system (``release_free_memory``), before the next one loads."""
    with tqdm(total=len(restorers), desc=f"{target.lens_name} restorers", leave=False) as bar:
        while restorers:
            _restore_and_score(restorers.pop(0), target, fitted, cfg, rows, out, readers)
            release_free_memory()
            bar.update()


def _restore_and_score(attacker: attacks.Restorer, target: Target, fitted: dict[str, dict], cfg: RunConfig,
                       rows: RowBuilder, out: Attacked, readers: Sequence[ReadyReader]) -> None:
    """One restorer of ``run_restorers``: restore, score, read with each reader."""
    # A reference (e.g. the uncorrected image) is reported, but never as an attack.
    kind = "reference" if getattr(attacker, "reference", False) else "restorer"
    described = describe(attacker)
    if isinstance(described, RowError):
        out.rows.append(rows.failed(kind, attacker.name, described, restorer=attacker.name))
        return
    settings = {"restorer": described}
    meta = fitted.get(attacker.name, {})
    if "skipped" in meta:
        log.info("%s on %s skipped: %s", attacker.name, target.lens_name, meta["skipped"])
        return
    if "error" in meta:
        out.rows.append(rows.failed(kind, attacker.name, RowError(**meta["error"]), restorer=attacker.name,
                                    settings=settings))
        return
    t0 = time.perf_counter()
    ctx = own_context(target.ctx, attacker.name)
    root = target.ctx.cache_dir
    error = attempt(attacker.name, "fit", lambda: attacker.fit(ctx), cfg.budget_s, root)  # normally a cache hit
    fit_s = meta.get("fit_s", time.perf_counter() - t0)  # fitted here when its task's result was not kept
    key = None if isinstance(error, RowError) else restoration_key(attacker)
    twin = out.by_key.get(key) if key is not None else None  # an earlier restorer of this run with its key
    if twin is not None:
        log.info("%s on %s restores as %s does (the same restoration_key): scored from its output",
                 attacker.name, target.lens_name, twin.name)
        restored = out.restored[twin.name]
        metrics, per_image = dict(twin.metrics), twin.per_image
    else:
        t0 = time.perf_counter()
        result = error if isinstance(error, RowError) else attempt(
            attacker.name, "restore", lambda: restore_all(attacker, target.sensor, cfg.profile.batch_size, cfg.device),
            cfg.budget_s, root)
        if isinstance(result, RowError):
            out.rows.append(rows.failed(kind, attacker.name, result, restorer=attacker.name, settings=settings))
            return
        restored = result
        del result  # `restored` alone holds the batch: it goes once scored (below)
        run_s = time.perf_counter() - t0
        # What each stage frees goes back to the system before the next (see native_memory): glibc
        # would otherwise hold it, and a restorer's step would add up its stages' transients.
        release_free_memory()
        metrics, per_image = restoration_metrics(restored, target.sharp)
        metrics["images_per_s"] = target.sharp.shape[0] / run_s
        if key is not None:
            out.by_key[key] = Restored(attacker.name, dict(metrics), per_image)
    record = out.by_key.get(key) if key is not None else None  # where the reads of this output are kept
    if target.plates is not None and twin is None:
        # Of the scenes only the sample picture's first one is kept (every restorer's 64 full scenes
        # would hold gigabytes); a clone, as a slice would keep the whole batch's storage alive.
        # Scored already, the frames go before the windows are restored and read.
        restored = restored[:1].clone()
    release_free_memory()
    images: torch.Tensor | list[torch.Tensor] = restored
    # Only the chains the run measures read this restorer's output (cfg.chains: the standard ensemble).
    readers = [r for r in readers if cfg.wants(chain_name(attacker.name, r.reader.name))]
    # A twin's reads of the windows are this restorer's; the windows are restored only for readers it lacks.
    known = twin.reads if twin is not None and target.plates is not None else {}
    to_read = [r for r in readers if r.reader.name not in known]
    if target.plates is not None and to_read:
        windows = attempt(attacker.name, "restore", lambda: restore_windows(
            attacker, target.plates.sensor, cfg.profile.batch_size, cfg.device),  # type: ignore[union-attr]
            cache_root=root)
        if isinstance(windows, RowError):
            out.rows.append(rows.failed(kind, attacker.name, windows, restorer=attacker.name, settings=settings))
            return
        images = windows
    out.restored[attacker.name] = restored
    out.described[attacker.name] = described
    out.threat_models[attacker.name] = attacker.threat_model
    out.learns[attacker.name] = attacker.learns
    if kind == "reference":
        out.references.add(attacker.name)
    for reader in readers:
        read = read_chain(target, reader, attacker.name, images, cfg, rows, out, known.get(reader.reader.name))
        if record is not None and target.plates is not None and read is not None:
            record.reads.setdefault(reader.reader.name, read)
        release_free_memory()
    del restored
    if target.plates is not None and to_read:
        out.restored_plates[attacker.name] = {i: images[i] for i in gallery_windows(target.plates)}
    elif twin is not None and twin.name in out.restored_plates:
        out.restored_plates[attacker.name] = out.restored_plates[twin.name]
    del images
    metrics["fit_s"] = float(fit_s)
    notes = {**fit_notes(error), LEARNS: _flag(attacker.learns)}
    if twin is not None:
        notes[RESTORED_AS] = twin.name
    row = rows.row(kind, metrics, attack=attacker.name, restorer=attacker.name,
                   threat_model=attacker.threat_model.value, settings=settings, notes=notes)
    scene_intervals(row, per_image, seed=row.seed)
    row.set_units(scene_units(target.scenes, per_image))
    out.rows.append(row)
    log.debug("%s on %s: resident memory %.2f GB", row.attack, target.lens_name, resident_gb())


RESTORED_AS = "restored_as"
"""Row note: the restorer of this run whose output this one's rows were scored from (the same
``restoration_key``: the same images for every input), its speed included."""


def restoration_key(attacker: attacks.Restorer) -> str | None:
    """The attacker's ``restoration_key`` after its fit; None where it makes no claim, or raises (logged: it is
    then restored on its own, as any restorer)."""
    try:
        key = attacker.restoration_key()
    except Exception as e:  # noqa: BLE001 - a plugin's claim that fails is no claim
        log.warning("%s.restoration_key raised %s: %s; restored on its own", attacker.name, type(e).__name__, e)
        return None
    return key if isinstance(key, str) else None


def resident_gb() -> float:
    """This process's resident set size now (Linux /proc; 0.0 where it cannot be read)."""
    try:
        return int(Path("/proc/self/statm").read_text().split()[1]) * os.sysconf("SC_PAGE_SIZE") / 1e9
    except (OSError, ValueError, IndexError):
        return 0.0


@dataclass
class ReadyReader:
    """A reader after its fit: `fit_error` is the RowError of its describe(), skip_reason() or fit
    (every chain of it is then a failed row), None when it fitted; `described` its describe()."""

    reader: attacks.Reader
    fit_error: RowError | None
    described: dict = field(default_factory=dict)
    notes: dict[str, str] = field(default_factory=dict)  # what its fit says of itself (`fit_notes`)
    fit_s: float | None = None  # the seconds its fit took here (a cache hit: the load)
    fit_recorded: bool = False  # whether a row carries fit_s yet (the first row read with it does)


def _flag(value: bool) -> str:
    return "true" if value else "false"


def fit_notes(report: object) -> dict[str, str]:
    """The row notes of an attacker's ``FitReport``: ``FIT_STILL_RISING`` ("true" / "false") when it says
    whether its fit stopped while its held-out score was still improving, and ``fit_stopped`` ("flattened
    at step 1200, kept step 900") when it has a curve. Anything but a FitReport gives none."""
    if not isinstance(report, attacks.FitReport):
        return {}
    notes = {}
    if isinstance(report.still_rising, bool):
        notes[FIT_STILL_RISING] = "true" if report.still_rising else "false"
    if report.curve is not None and report.curve.steps:
        curve = report.curve
        notes["fit_stopped"] = f"{curve.stopped} at step {curve.steps[-1]}, kept step {curve.kept_step}"
    return notes


def fit_readers(target: Target, readers: Sequence[attacks.Reader], cfg: RunConfig) -> list[ReadyReader]:
    """Fit each reader that does not skip this target (a skip is logged), each on its own context."""
    ready = []
    for reader in readers:
        described = describe(reader)
        if isinstance(described, RowError):
            ready.append(ReadyReader(reader, described))
            continue
        ctx = own_context(target.ctx, reader.name)
        reason = attempt(reader.name, "fit", lambda: reader.skip_reason(ctx), cache_root=target.ctx.cache_dir)
        if reason and not isinstance(reason, RowError):
            log.info("%s on %s skipped: %s", reader.name, target.lens_name, reason)
            continue
        t0 = time.perf_counter()
        error = reason if isinstance(reason, RowError) else attempt(reader.name, "fit", lambda: reader.fit(ctx),
                                                                     cfg.budget_s, target.ctx.cache_dir)
        if isinstance(error, RowError):
            ready.append(ReadyReader(reader, error, described))
            continue
        fit_s = time.perf_counter() - t0
        # The settings keep the description made before the fit; the fit's report on itself goes in the notes.
        after = describe(reader)
        ready.append(ReadyReader(reader, after if isinstance(after, RowError) else None, described, fit_notes(error),
                                 fit_s))
    return ready


def read_chain(target: Target, ready: ReadyReader, restorer: str | None,
               images: torch.Tensor | Sequence[torch.Tensor], cfg: RunConfig, rows: RowBuilder, out: Attacked,
               known: ReadResult | None = None, as_reference: bool = False) -> ReadResult | None:
    """Read `images` (the sensor's when `restorer` is None, else that restorer's output; plate
    windows when the target has them) with one fitted reader and score the chain. `known`: that read
    already made, of the same images (a twin restorer's, ``Restored``); it is scored instead of reading.
    `as_reference`: a target nothing restores (the sharp scenes), which every reader of the run reads as it
    is, whether the run reads with it on the sensor image or only after restorers.
    Returns the read (None where the chain was not read)."""
    reader = ready.reader
    chain = reader.name if restorer is None else chain_name(restorer, reader.name)
    if not (cfg.reads_with(reader.name) if as_reference else cfg.wants(chain)):  # not a chain of the run's ensemble (cfg.chains)
        return None
    kind = "reader" if restorer is None else "reference" if restorer in out.references else "chain"
    settings = {"reader": ready.described, **({"restorer": out.described[restorer]} if restorer else {})}
    chain_rows = out.reader_rows.setdefault(reader.name, [])
    if ready.fit_error is not None:
        chain_rows.append(rows.failed(kind, chain, ready.fit_error, restorer=restorer, reader=reader.name,
                                      settings=settings))
        return None
    # The attacker with device access segments sensor images with the lens's own network,
    # restored images with the clean one.
    segment = target.segment_sensor if restorer is None else target.segment_restored
    plate_scenes = target.scenes if target.plates is None else target.plates.scenes
    if not any(s.plates for s in plate_scenes):  # e.g. --scenes photos: a sentence, not a ZeroDivisionError
        error = RowError(reader.name, "read", f"the scenes {cfg.scenes!r} hold no licence plates, so the plate "
                         f"reader {reader.name!r} has nothing to read; read plates on synthetic scenes or on "
                         "cityscapes:PATH with plate annotations")
        chain_rows.append(rows.failed(kind, chain, error, restorer=restorer, reader=reader.name, settings=settings))
        return None
    result = known if known is not None else attempt(
        reader.name, "read", lambda: read_plates(reader, images, plate_scenes, cfg.profile.batch_size, cfg.device,
                                                 segment), cfg.budget_s, target.ctx.cache_dir)
    if isinstance(result, RowError):
        chain_rows.append(rows.failed(kind, chain, result, restorer=restorer, reader=reader.name, settings=settings))
        return None
    outcomes, timing, out.reads[chain] = result
    timing = dict(timing)
    if target.plates is not None:
        timing["n_frames"] = float(target.plates.n_frames)
    # The first row read with the reader carries its fit: its own on the sensor image where the run has that
    # row, else its first chain (a reader that reads only after restorers); the others do not.
    if ready.fit_s is not None and not ready.fit_recorded:
        timing["fit_s"], ready.fit_recorded = ready.fit_s, True
    # A chain needs what its strongest part needs (a known-PSF restorer's lens access, say).
    threat = reader.threat_model if restorer is None else attacks.ThreatModel.strongest(
        reader.threat_model, out.threat_models[restorer])
    row = plate_row(rows, kind, chain, outcomes, timing, restorer=restorer, reader=reader.name,
                    threat_model=threat.value, settings=settings,
                    notes={**ready.notes, LEARNS: _flag(ready.reader.learns or out.learns.get(restorer or "", False))})
    chain_rows.append(row)
    out.reader_plates.setdefault(reader.name, []).extend(plate_records(target, row, outcomes))
    return result


def plate_row(rows: RowBuilder, kind: str, chain: str, outcomes: list[PlateOutcome], metrics: dict[str, float],
              **fields: Any) -> Row:
    """A reader or chain row scored from its per-plate outcomes: its pooled figures (and their intervals)
    count the readable plates, its units hold every scored plate (from 8 px); `metrics` and `fields`
    (restorer, reader, threat_model, settings, notes) are added as given."""
    readable_outcomes = pooled(outcomes)
    row = rows.row(kind, {**summarise(readable_outcomes), **metrics}, attack=chain, **fields)
    plate_intervals(row, readable_outcomes)
    row.set_units(plate_units(outcomes))
    return row


def plate_records(target: Target, row: Row, outcomes: list[PlateOutcome]) -> list[dict]:
    """The run's per-plate records (plates.csv) of one scored row."""
    return [{"lens": target.lens_name, "attack": row.attack, "seed": row.seed, **o.__dict__} for o in outcomes]


def read_sensor(target: Target, readers: Sequence[ReadyReader], cfg: RunConfig, rows: RowBuilder, out: Attacked,
                as_reference: bool = False) -> None:
    """Each reader on the sensor images (the plate windows when the target has them); `as_reference` as
    `read_chain` takes it."""
    for ready in readers:
        read_chain(target, ready, None, target.sensor if target.plates is None else target.plates.sensor,
                   cfg, rows, out, as_reference=as_reference)


def run_reader(target: Target, reader: attacks.Reader, cfg: RunConfig, rows: RowBuilder, out: Attacked) -> None:
    """Fit `reader`, read the sensor images and every restored set already in `out`, score each
    chain; its rows go to `out.rows` (for a target without restorers, e.g. the sharp scenes, which it reads
    whenever the run reads with it at all: `read_chain`'s `as_reference`)."""
    if not cfg.reads_with(reader.name):
        return
    for ready in fit_readers(target, [reader], cfg):
        read_sensor(target, [ready], cfg, rows, out, as_reference=True)
        for name, images in (out.restored if target.plates is None else {}).items():
            read_chain(target, ready, name, images, cfg, rows, out)
    out.finish()


def gallery_windows(plates: PlateSet, max_plates: int = 8) -> list[int]:
    """Indices of the plate windows the run's plate gallery shows: the most common window size
    (its images must stack), at most `max_plates` of them, widest readable plates first (the
    gallery's own order, benchmark.results.charts.plate_gallery)."""
    shapes = [tuple(t.shape) for t in plates.sharp]
    if not shapes:
        return []
    common = max(set(shapes), key=shapes.count)
    pick = [i for i, shape in enumerate(shapes) if shape == common]
    widths = {i: max((p.box_xyxy[2] - p.box_xyxy[0] for p in plates.scenes[i].plates if readable(p)), default=-1)
              for i in pick}
    return sorted(sorted(pick, key=lambda i: -widths[i])[:max_plates])
