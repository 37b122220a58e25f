"""Run one planned task (`benchmark.runner.planning`) unless its result is cached; the task bodies.

A task's result (its rows, the settings they point at, plate records and metadata) is a
verified JSON file in a folder named after the task, inside the run's folder of the cache, so a
task can run on any machine that sees the cache and re-running it is a no-op. Several runs may
share the cache: a per-task lock makes one of them compute and the others read its result; a
corrupt result is reported with its path and recomputed.
"""

from __future__ import annotations

import functools
import hashlib
import json
import logging
import os
import shutil
import time
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np
import torch

import attacks
import lenses
from benchmark.runner.diagnostics import profiling
from benchmark.runner import task_costs
from benchmark.runner.attacker_objects import load as load_attacker
from benchmark.runner.budget import BudgetExceeded, time_budget
from benchmark.results.charts import encrypted_pictures
from benchmark.store import cipher
from benchmark.store.cache import (CHECKSUM_SUFFIX, ArtifactCache, discard, exclusive, read_verified, seal,
                                   write_verified)
from benchmark.codesign.trainer import TRAINER_VERSION
from benchmark.runner.evaluation import Attacked, PlateSet, Target, attempt, fit_readers, read_sensor, run_reader, run_restorers
from benchmark.runner.isolation import own_context
from benchmark.runner.cascade import run_cascade, wanted_readers
from benchmark.runner.intervals import utility_intervals
from benchmark.runner.planning import AttackerRef, Task, fit_task
from benchmark.results.plate_scoring import READABLE_MIN_WIDTH_PX, SCORED_MIN_WIDTH_PX, WIDTH_BINS_PX, scored
from benchmark.scenes.plate_spectrum import cached_plate_spectrum
from benchmark.store.provenance import provenance
from benchmark.runner.rows import RowBuilder, training_facts, utility_units
from benchmark.runner.pictures import plate_gallery, sample_grid, training_curves
from benchmark.runner.config import RunConfig, training_scenes
from benchmark.scenes import Plate, Scene, load_scene, load_scenes, plate_entropy_bits
from benchmark.scenes.windows import WidthQuota, plate_windows, window_scene
from benchmark.results.schema import Row, RowError
from benchmark.runner.sensing import sense, sense_windows, to_tensor, train_pairs_factory
from benchmark.runner.utility_measure import has_labels, segmenter, utility_net_for, utility_scores
from benchmark.codesign.utility.scoring import window_for
from lenses.bound import bound_curve, bound_row
from benchmark.codesign.utility.clean import clean_utility_net

log = logging.getLogger(__name__)

BOUND_CURVE_WIDTHS_PX = (4, 8, 12, 16, 24, 32, 48, 64, 96, 128, 192)
# The plate set stops drawing frames here even short of its target (a scene set with few plates).
# The plate set fills every width bin below this to its full quota (>= 50 plates per bin from 8 to 64 px).
QUOTA_BELOW_PX = 64
RESULT_FILE = "result.json"
# The tasks that hold the val scenes' plates: a sealed run encrypts their pictures (cipher).
SCENE_TASKS = ("sharp", "evaluate")


@dataclass
class TaskResult:
    """What a task produced: rows, the settings they point at (hash -> settings), plates, metadata."""

    rows: list[Row] = field(default_factory=list)
    settings: dict[str, dict] = field(default_factory=dict)
    plates: list[dict] = field(default_factory=list)
    meta: dict = field(default_factory=dict)

    @property
    def has_failures(self) -> bool:
        """True when a row failed or the task recorded an error: such a result is not reused by a
        later run (the attacker may have been fixed since), only within the run that made it."""
        return "error" in self.meta or any(not r.ok for r in self.rows)

    def to_json(self) -> dict[str, Any]:
        return {"rows": [r.to_json() for r in self.rows], "settings": self.settings, "plates": self.plates,
                "meta": self.meta}

    @classmethod
    def from_json(cls, d: dict[str, Any]) -> TaskResult:
        return cls([Row.from_json(r) for r in d["rows"]], d["settings"], d["plates"], d["meta"])


def load_result(directory: Path, task: Task, key: bytes | None = None) -> TaskResult | None:
    """The task's stored result, or None when absent or corrupt (reported with its path, removed);
    `key`: a sealed run's (``cipher.run_key``), which its results are encrypted under."""
    path = directory / task.key / RESULT_FILE
    data = read_verified(path)
    if data is None:
        return None
    try:
        result = TaskResult.from_json(json.loads(cipher.plain(key, RESULT_FILE, data)))
    except (ValueError, KeyError, TypeError) as exc:  # verified bytes of an older layout, or another key's
        log.warning("unreadable task result %s (%s); it will be recomputed", path, exc)
        discard(path)
        return None
    # Its pictures are checked like the result: a truncated or altered one (reported and removed by
    # read_verified) would otherwise be copied into the run and published.
    if any(read_verified(path.parent / name) is None for name in result.meta.get("pictures", [])):
        log.warning("task result %s lost a picture; it will be recomputed", path)
        discard(path)
        return None
    return result


def is_cached(directory: Path, task: Task) -> bool:
    """Whether a run would reuse the task's stored result: present, matching its checksum, readable
    and without failures (see `execute`). Read-only, unlike `load_result` (a corrupt result stays
    for the run to report), so a dry run changes nothing."""
    path = directory / task.key / RESULT_FILE
    try:
        data = path.read_bytes()
        expected = path.with_name(path.name + CHECKSUM_SUFFIX).read_text().strip()
    except FileNotFoundError:
        return False
    if hashlib.sha256(data).hexdigest() != expected:
        return False
    try:
        result = TaskResult.from_json(json.loads(data))
    except (ValueError, KeyError, TypeError):  # verified bytes of an older layout
        return False
    return not result.has_failures and all(_intact(path.parent / name) for name in result.meta.get("pictures", []))


def _intact(path: Path) -> bool:
    """Whether `path` matches its checksum sidecar (read-only)."""
    try:
        data = path.read_bytes()
        expected = path.with_name(path.name + CHECKSUM_SUFFIX).read_text().strip()
    except FileNotFoundError:
        return False
    return hashlib.sha256(data).hexdigest() == expected


def execute(task: Task, cfg: RunConfig, directory: Path) -> TaskResult:
    """Run one task unless its result exists; publish the result folder in one rename.

    The per-task lock lets one run compute while others sharing the cache wait and read its
    result; staging folders are removed only under that lock, i.e. only when their owner is gone,
    or by the task itself when it fails. A stored result with failures is computed again. A
    lens's task that raises gives failed rows (`failed_result`) instead of ending the run, so the
    other lenses' results are complete.
    """
    key = cipher.run_key(cfg.scene_seeds)
    done = load_result(directory, task, key)
    if done is not None and not done.has_failures:
        return done
    directory.mkdir(parents=True, exist_ok=True)
    with exclusive(directory / f".{task.key}.lock"):
        done = load_result(directory, task, key)  # another run finished it while this one waited
        if done is not None and not done.has_failures:
            return done
        for stale in directory.glob(f".{task.key}.staging-*"):  # left by a run that died mid-task
            shutil.rmtree(stale, ignore_errors=True)
        staging = directory / f".{task.key}.staging-{os.getpid()}-{time.monotonic_ns()}"
        staging.mkdir(parents=True)
        t0 = time.perf_counter()
        try:
            # A sealed run's tasks that see the val scenes write their pictures encrypted (cipher).
            encrypt = None if key is None or task.kind not in SCENE_TASKS else functools.partial(cipher.encrypt, key)
            with profiling.task_scope(task), encrypted_pictures(encrypt):  # profiling: a no-op unless --profile-time
                result = _KINDS[task.kind](task, cfg, staging)
        except Exception as exc:
            shutil.rmtree(staging)
            failed = failed_result(task, cfg, exc)
            if failed is None:
                raise
            staging.mkdir()
            result = failed
        except BaseException:
            shutil.rmtree(staging)
            raise
        wall_s = time.perf_counter() - t0
        for name in result.meta.get("pictures", []):
            seal(staging / name)  # checked with the result when it is reused (load_result)
        for row in result.rows:
            row.provenance["wall_s"] = wall_s
        task_costs.record(staging, task, cfg, wall_s)  # what a dry run's estimates are made of
        data = json.dumps(result.to_json(), default=str, allow_nan=False).encode()
        write_verified(staging / RESULT_FILE, data if key is None else cipher.encrypt(key, RESULT_FILE, data))
        final = directory / task.key
        if final.exists():  # a corrupt result, or one with failures
            shutil.rmtree(final)
        os.replace(staging, final)
    loaded = load_result(directory, task, key)
    if loaded is None:
        raise RuntimeError(f"task {task.key}: its result {directory / task.key / RESULT_FILE} vanished after writing")
    return loaded


def failed_result(task: Task, cfg: RunConfig, exc: Exception) -> TaskResult | None:
    """The result of a lens's task that raised: a failed row per row it would have made (the fit of
    a restorer records the error for its evaluate task); None for a per-seed task, whose failure
    every lens shares (it ends the run). The traceback goes to the log."""
    if not task.lens:
        return None
    log.error("task %s failed", task.key, exc_info=exc)
    message = f"{type(exc).__name__}: {exc} (task {task.key}; traceback in the log)"
    builder = _builder(cfg, task.lens, task.seed, None)
    if task.kind == "fit":
        return TaskResult(meta={"error": RowError(task.restorers[0].name, "fit", message).to_json()})
    if task.kind in ("lens", "utility", "bound"):
        return TaskResult([builder.failed(task.kind, task.kind, RowError(task.kind, "measure", message))],
                          builder.settings)
    rows = [builder.failed("restorer", r.name, RowError(r.name, "measure", message), restorer=r.name)
            for r in task.restorers]
    rows += [builder.failed("reader", r.name, RowError(r.name, "measure", message), reader=r.name)
             for r in task.readers]
    return TaskResult(rows, builder.settings)


# ---- helpers of the task bodies ----------------------------------------------------------------

def _scenes(cfg: RunConfig, seed: int) -> list[Scene]:
    return load_scenes(cfg.scenes, "val", cfg.profile.n_val, cfg.profile.image_size, cfg.scene_seed(seed))


def plate_set(cfg: RunConfig, seed: int, lens: lenses.Lens | None) -> PlateSet | None:
    """The plate windows of `seed` (benchmark.scenes.windows; of its scene seed, `RunConfig.scene_seed`)
    seen through `lens` (None: the sharp windows); None when the profile reads plates on the n_val scenes
    themselves.

    Val frames are drawn in order, one at a time (only the windows are kept), and a scored plate is
    taken while its width bin (WIDTH_BINS_PX) holds fewer than the profile's `plates_per_width_bin`
    (`plates_per_wide_bin` from QUOTA_BELOW_PX, whose windows are the large ones), until every bin
    below QUOTA_BELOW_PX is full or `plate_frames` frames are drawn. So the small plates, rare in a
    street scene, are as many as the large ones. Each window is at least the utility net's sliding
    window.
    """
    profile = cfg.profile
    if profile.plates_per_width_bin <= 0:
        return None
    quota = WidthQuota(WIDTH_BINS_PX, [profile.plates_per_width_bin if low < QUOTA_BELOW_PX
                                       else profile.plates_per_wide_bin for low in WIDTH_BINS_PX], QUOTA_BELOW_PX)
    min_size = window_for(profile.image_size, profile.train_crop)[0]

    def take(plate: Plate) -> bool:
        return scored(plate) and quota.take(plate.box_xyxy[2] - plate.box_xyxy[0])

    scenes: list[Scene] = []
    sharp: list[torch.Tensor] = []
    sensor: list[torch.Tensor] = []
    n_frames = 0
    while not quota.full and n_frames < profile.plate_frames:
        frame = load_scene(cfg.scenes, "val", n_frames, profile.image_size, cfg.scene_seed(seed))
        n_frames += 1
        windows = plate_windows([frame], take, min_size)
        if not windows:
            continue
        scenes += [window_scene(frame, w) for w in windows]
        sharp += [torch.from_numpy(np.ascontiguousarray(s.image)).permute(2, 0, 1) for s in scenes[-len(windows):]]
        sensor += sharp[-len(windows):] if lens is None else sense_windows(lens, [frame], windows, seed, cfg.device)
    if not quota.full:
        short = {f"{low} px": c for low, c in zip(WIDTH_BINS_PX, quota.counts) if low < QUOTA_BELOW_PX
                 and c < profile.plates_per_width_bin}
        log.warning("plate set of seed %d: %d frames drawn (the profile's plate_frames) left width bins short of "
                    "%d plates: %s", seed, n_frames, profile.plates_per_width_bin, short)
    # Equal window sizes next to each other, so that restorers and readers batch them.
    order = sorted(range(len(scenes)), key=lambda i: (tuple(sharp[i].shape), i))
    return PlateSet([scenes[i] for i in order], [sharp[i] for i in order], [sensor[i] for i in order], n_frames)


def _clean_net(cfg: RunConfig, seed: int, scenes: list[Scene]) -> torch.nn.Module | None:
    if not has_labels(scenes):
        return None
    return clean_utility_net(cfg.profile, seed, cfg.device, cfg.cache_dir, training_scenes(cfg.scenes),
                            progress=False)


def _lens(cfg: RunConfig, name: str, seed: int) -> lenses.Lens:
    return lenses.load(cfg.lens_source(name), profile=cfg.profile, seed=seed, device=cfg.device, cache_dir=cfg.cache_dir,
                       scenes=training_scenes(cfg.scenes)).to(cfg.device)


def _builder(cfg: RunConfig, lens_name: str, seed: int, lens: lenses.Lens | None, **extra: Any) -> RowBuilder:
    settings = {"lens": lens.current_spec().to_dict() if lens is not None else lens_name,
                "profile": cfg.profile.to_dict(), "scenes": cfg.scenes, "seed": seed,
                # Which plates get outcomes and which count in the pooled plate figures.
                "plates_px": {"scored_from": SCORED_MIN_WIDTH_PX, "readable_from": READABLE_MIN_WIDTH_PX}, **extra}
    return RowBuilder(cfg, lens_name, seed, settings, provenance(cfg.device))


def fit_context(lens: lenses.Lens | None, cfg: RunConfig, seed: int,
                segment: Callable[[torch.Tensor], torch.Tensor] | None) -> attacks.FitContext:
    """What an attacker of this lens may use: the lens (and its co-design adversary, if any), training
    pairs, cache, device, seed, the profile's attack budget, the lens's segmenter and the run's plate format
    (what the bound counts; the scenes' own unless the run names another)."""
    folder = Path(cfg.cache_dir) / "attacks"
    return attacks.FitContext(lens=lens, train_pairs=None if lens is None else train_pairs_factory(lens, cfg, seed),
                              cache_dir=folder, artifacts=ArtifactCache(folder), device=cfg.device, seed=seed,
                              budget=cfg.profile.attack_budget(), segmenter=segment, plate_format=cfg.plate_format,
                              adversary=None if lens is None else lens.adversary)


def _load_attackers(refs: tuple[AttackerRef, ...], kind: type[attacks.Attack], builder: RowBuilder
                    ) -> tuple[list[Any], list[Row]]:
    """The attackers of `refs` that load; a failed row per attacker that does not."""
    loaded, failed = [], []
    for ref in refs:
        attacker = attempt(ref.name, "load", lambda: load_attacker(ref.spec))
        if isinstance(attacker, RowError):
            if kind is attacks.Reader:
                failed.append(builder.failed("reader", ref.name, attacker, reader=ref.name))
            else:
                failed.append(builder.failed("restorer", ref.name, attacker, restorer=ref.name))
        elif isinstance(attacker, kind):
            loaded.append(attacker)
    return loaded, failed


# ---- task bodies -----------------------------------------------------------------------------

def _clean_utility(task: Task, cfg: RunConfig, _: Path) -> TaskResult:
    _clean_net(cfg, task.seed, _scenes(cfg, task.seed))
    return TaskResult()


def _spectrum(task: Task, cfg: RunConfig, _: Path) -> TaskResult:
    cached_plate_spectrum(cfg.cache_dir, cfg.profile.bound_scenes, seed=task.seed)
    return TaskResult()


def _sharp(task: Task, cfg: RunConfig, _: Path) -> TaskResult:
    """Rows measured on the sharp scenes themselves (lens `sharp`, the paper's "Original"):
    the clean utility net's scores and every reader."""
    scenes = _scenes(cfg, task.seed)
    sharp = to_tensor(scenes)
    clean = _clean_net(cfg, task.seed, scenes)
    builder = _builder(cfg, "sharp", task.seed, None)
    rows: list[Row] = []
    if clean is not None:
        metrics, confusion = utility_scores(clean, sharp, scenes, cfg)
        row = builder.row("utility", metrics)
        utility_intervals(row, confusion)
        row.set_units(utility_units(scenes, confusion))
        rows.append(row)
    segment = segmenter(clean, cfg) if clean is not None else None
    target = Target("sharp", scenes, sharp, sharp, fit_context(None, cfg, task.seed, segment), segment, segment,
                    plates=plate_set(cfg, task.seed, None))
    readers, failed = _load_attackers(task.readers, attacks.Reader, builder)
    out = Attacked(rows=rows + failed)
    for reader in readers:  # a reader that skips the sharp scenes is left out by run_reader
        run_reader(target, reader, cfg, builder, out)
    return TaskResult(out.rows, builder.settings, out.plates)


def _lens_task(task: Task, cfg: RunConfig, staging: Path) -> TaskResult:
    t0 = time.perf_counter()
    # Co-designing a lens is a run's longest step: --budget-s covers it (past it, the lens's rows fail).
    with time_budget(cfg.budget_s, f"lens {task.lens!r} (its co-design or load)"):
        lens = _lens(cfg, task.lens, task.seed)
    fit_s = time.perf_counter() - t0
    sharp = to_tensor(_scenes(cfg, task.seed))
    t0 = time.perf_counter()
    sense(lens, sharp, cfg.profile.batch_size, task.seed, cfg.device)
    speed = sharp.shape[0] / (time.perf_counter() - t0)
    with torch.no_grad():  # a co-designed lens's coefficients are parameters: no graph for a figure
        energy = float(lens.psf_and_energy()[1].min())
    metrics = {"images_per_s": speed, "fit_s": fit_s, "psf_size_px": float(lens.geometry.psf_size_px),
               "psf_energy": energy}
    builder = _builder(cfg, task.lens, task.seed, lens)
    spec = lens.current_spec()
    facts, notes = training_facts(getattr(lens, "training_record", None))
    curves = training_curves(lens, task.seed, cfg.cache_dir, staging)
    return TaskResult([builder.row("lens", {**metrics, **facts}, notes=notes)], builder.settings,
                      meta={"coefficients_um": list(spec.mask.zernike_um), "spec": spec.to_dict(),
                            "pictures": [curves] if curves else []})


def _utility(task: Task, cfg: RunConfig, _: Path) -> TaskResult:
    scenes = _scenes(cfg, task.seed)
    if not has_labels(scenes):
        return TaskResult()
    lens = _lens(cfg, task.lens, task.seed)
    net, fit_s = utility_net_for(lens, task.lens, task.seed, cfg)
    sensor = sense(lens, to_tensor(scenes), cfg.profile.batch_size, task.seed, cfg.device)
    metrics, confusion = utility_scores(net, sensor, scenes, cfg, lens)
    builder = _builder(cfg, task.lens, task.seed, lens)
    row = builder.row("utility", {**metrics, "fit_s": fit_s},
                      notes={"utility_input": "sensor image white-balanced by the sensor's known gain",
                             # the net was trained (or found in the cache, keyed by it) by this trainer
                             "trainer_version": str(TRAINER_VERSION)})
    utility_intervals(row, confusion)
    row.set_units(utility_units(scenes, confusion))
    return TaskResult([row], builder.settings)


def _bound(task: Task, cfg: RunConfig, _: Path) -> TaskResult:
    lens = _lens(cfg, task.lens, task.seed)
    spectrum = cached_plate_spectrum(cfg.cache_dir, cfg.profile.bound_scenes, seed=task.seed)
    bits = plate_entropy_bits(cfg.plate_format)
    builder = _builder(cfg, task.lens, task.seed, lens, plate_format=cfg.plate_format, frames=cfg.frames)
    t0 = time.perf_counter()
    try:
        with time_budget(cfg.budget_s, f"the bound of lens {task.lens!r}"):
            values = bound_row(lens, spectrum, bits, frames=tuple(sorted({1, cfg.frames})))
            curve = bound_curve(lens, spectrum, list(BOUND_CURVE_WIDTHS_PX), bits)
    except BudgetExceeded as exc:
        return TaskResult([builder.failed("bound", "bound", RowError("bound", "measure", str(exc)))], builder.settings)
    metrics = {k: float(v) for k, v in values.items() if not isinstance(v, str)}
    metrics["fit_s"] = time.perf_counter() - t0
    notes = {k: v for k, v in values.items() if isinstance(v, str)}
    notes["bound_plate_format"] = cfg.plate_format
    return TaskResult([builder.row("bound", metrics, notes=notes)], builder.settings,
                      meta={"curve": {k: [float(x) for x in v] for k, v in curve.items()}})


def _fit(task: Task, cfg: RunConfig, _: Path) -> TaskResult:
    """Fit one restorer; its failure is recorded (meta "error"), never raised."""
    (ref,) = task.restorers
    attacker = attempt(ref.name, "load", lambda: load_attacker(ref.spec))
    if isinstance(attacker, RowError):
        return TaskResult(meta={"error": attacker.to_json()})
    shared = fit_context(_lens(cfg, task.lens, task.seed), cfg, task.seed, None)
    ctx, root = own_context(shared, ref.name), shared.cache_dir
    reason = attempt(ref.name, "fit", lambda: attacker.skip_reason(ctx), cache_root=root)
    if isinstance(reason, RowError):
        return TaskResult(meta={"error": reason.to_json()})
    if reason:
        return TaskResult(meta={"skipped": reason})
    t0 = time.perf_counter()
    error = attempt(ref.name, "fit", lambda: attacker.fit(ctx), cfg.budget_s, root)
    if isinstance(error, RowError):
        return TaskResult(meta={"error": error.to_json()})
    return TaskResult(meta={"fit_s": time.perf_counter() - t0})


def _evaluate(task: Task, cfg: RunConfig, staging: Path) -> TaskResult:
    """Every restorer and every reader chain on one lens and seed; sample pictures into `staging`."""
    lens = _lens(cfg, task.lens, task.seed)
    scenes = _scenes(cfg, task.seed)
    sharp = to_tensor(scenes)
    clean = _clean_net(cfg, task.seed, scenes)
    lens_net = utility_net_for(lens, task.lens, task.seed, cfg)[0] if clean is not None else None
    segment_sensor = segmenter(lens_net, cfg, lens) if lens_net is not None else None
    target = Target(task.lens, scenes, sharp, sense(lens, sharp, cfg.profile.batch_size, task.seed, cfg.device),
                    fit_context(lens, cfg, task.seed, segment_sensor), segment_sensor,
                    segmenter(clean, cfg) if clean is not None else None, plate_set(cfg, task.seed, lens))
    builder = _builder(cfg, task.lens, task.seed, lens)
    restorers, failed_restorers = _load_attackers(task.restorers, attacks.Restorer, builder)
    readers, failed_readers = _load_attackers(task.readers, attacks.Reader, builder)
    fitted = {ref.name: _fit_meta(staging.parent, task, ref, cipher.run_key(cfg.scene_seeds)) for ref in task.restorers}
    out = Attacked(rows=failed_restorers + failed_readers)
    ready = fit_readers(target, readers, cfg)
    read_sensor(target, ready, cfg, builder, out)
    # Each restorer's output is read by every reader right away (run_restorers), then dropped.
    run_restorers(target, restorers, fitted, cfg, builder, out, ready)
    out.finish()
    for cascading in wanted_readers(cfg, ready):  # last: it reads only what no chain above read
        run_cascade(target, cascading, cfg, builder, out)
    pictures = [sample_grid(target, lens, out, staging)]
    for r in ready:
        gallery = plate_gallery(target, out, r.reader.name, staging)
        pictures += [gallery] if gallery else []
    return TaskResult(out.rows, builder.settings, out.plates, meta={"pictures": pictures})


def _fit_meta(directory: Path, task: Task, ref: AttackerRef, key: bytes | None) -> dict:
    """The meta of the restorer's fit task; {} when another run is just redoing it (the evaluate
    task then fits the restorer itself)."""
    done = load_result(directory, fit_task(task.seed, task.lens, ref, lens_tag=task.lens_tag), key)
    return {} if done is None else done.meta


_KINDS: dict[str, Callable[[Task, RunConfig, Path], TaskResult]] = {
    "clean-utility": _clean_utility, "spectrum": _spectrum, "sharp": _sharp, "lens": _lens_task,
    "utility": _utility, "bound": _bound, "fit": _fit, "evaluate": _evaluate}
