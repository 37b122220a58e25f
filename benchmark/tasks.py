"""A run as a graph of tasks, each producing an artifact addressed by its key, written atomically.

Tasks per seed: `clean-utility` (the shared clean segmentation net), `spectrum` (plate spectrum
of the bound), `sharp` (reference rows on the sharp scenes); per lens and seed: `lens` (train or
load it; lens row), `utility`, `bound`, `fit` (one per restorer: train or load it), and `evaluate`
(restore with every restorer, read with every reader on the sensor image and on each restored
image, sample pictures). Trained networks live in the cache under their own config hash; a task's
result (its rows, plate records and metadata) is a JSON file in a directory named after the run's
config hash, so a task can run on any machine that sees the cache, and re-running it is a no-op.
"""

from __future__ import annotations

import json
import os
import shutil
import time
from dataclasses import dataclass, field
from pathlib import Path

import torch

import attacks
import lenses
from benchmark import runner as R
from benchmark.cache import config_hash
from benchmark.plate_spectrum import cached_plate_spectrum
from benchmark.provenance import git_commit, provenance
from benchmark.scenes import load_scenes
from benchmark.scenes import plate_entropy_bits
from lenses.bound import bound_curve
from benchmark.codesign.trainer import pretrain_utility

TASK_VERSION = 1
BOUND_CURVE_WIDTHS_PX = (4, 8, 12, 16, 24, 32, 48, 64, 96, 128, 192)


@dataclass(frozen=True)
class Task:
    kind: str
    seed: int
    lens: str = ""
    attack: str = ""
    deps: tuple[str, ...] = ()
    cpus: float = 1.0  # what the task asks a cluster scheduler for
    gpus: float = 0.0

    @property
    def key(self) -> str:
        parts = [self.kind, f"s{self.seed}", self.lens, self.attack]
        text = "_".join(p for p in parts if p)
        return "".join(c if c.isalnum() or c in "-_." else "-" for c in text)


@dataclass
class TaskResult:
    rows: list[dict] = field(default_factory=list)
    plates: list[dict] = field(default_factory=list)
    meta: dict = field(default_factory=dict)


def run_directory(cfg: R.RunConfig) -> Path:
    """Where a run's task results live: one folder per (configuration, code version)."""
    key = config_hash({"version": TASK_VERSION, "commit": git_commit(), "lenses": cfg.lenses, "attacks": cfg.attacks,
                       "scenes": cfg.scenes, "profile": cfg.profile.to_dict(), "seeds": cfg.seeds,
                       "device": cfg.device, "plate_format": cfg.plate_format, "frames": cfg.frames})
    return Path(cfg.cache_dir) / "tasks" / key


def plan(cfg: R.RunConfig, restorers: list[str], readers: list[str]) -> list[Task]:
    """Tasks in an order that respects their dependencies."""
    gpu = 1.0 if cfg.device.startswith("cuda") else 0.0
    tasks: list[Task] = []
    for seed in cfg.seeds:
        clean = Task("clean-utility", seed, cpus=2, gpus=gpu)
        spectrum = Task("spectrum", seed)
        tasks += [clean, spectrum, Task("sharp", seed, attack=",".join(readers), deps=(clean.key,), gpus=gpu)]
        for lens in cfg.lenses:
            t_lens = Task("lens", seed, lens, deps=(clean.key,), cpus=2, gpus=gpu)
            t_util = Task("utility", seed, lens, deps=(t_lens.key, clean.key), cpus=2, gpus=gpu)
            t_bound = Task("bound", seed, lens, deps=(t_lens.key, spectrum.key))
            fits = [Task("fit", seed, lens, name, deps=(t_lens.key,), cpus=2, gpus=gpu) for name in restorers]
            t_eval = Task("evaluate", seed, lens, ",".join(restorers + ["|"] + readers),
                          deps=(t_lens.key, t_util.key, *(f.key for f in fits)), cpus=2, gpus=gpu)
            tasks += [t_lens, t_util, t_bound, *fits, t_eval]
    return tasks


def load_result(directory: Path, task: Task) -> TaskResult | None:
    path = directory / task.key / "result.json"
    if not path.is_file():
        return None
    d = json.loads(path.read_text())
    return TaskResult(d["rows"], d["plates"], d["meta"])


def execute(task: Task, cfg: R.RunConfig, directory: Path) -> TaskResult:
    """Run one task unless its result exists; publish the result directory in one rename."""
    done = load_result(directory, task)
    if done is not None:
        return done
    directory.mkdir(parents=True, exist_ok=True)
    for stale in directory.glob(f".{task.key}.staging-*"):  # left by a worker that died mid-task
        shutil.rmtree(stale, ignore_errors=True)
    staging = directory / f".{task.key}.staging-{os.getpid()}-{time.monotonic_ns()}"
    staging.mkdir(parents=True)
    t0 = time.perf_counter()
    result = _KINDS[task.kind](task, cfg, staging)
    for row in result.rows:
        row["wall_s"] = time.perf_counter() - t0
    (staging / "result.json").write_text(json.dumps(
        {"rows": result.rows, "plates": result.plates, "meta": result.meta}, default=str))
    final = directory / task.key
    if final.exists():  # another worker finished it first (a retried task): keep theirs
        shutil.rmtree(staging)
    else:
        os.replace(staging, final)
    return load_result(directory, task)  # type: ignore[return-value]


# ---- task bodies -----------------------------------------------------------------------------

def _scenes(cfg: R.RunConfig, seed: int):
    return load_scenes(cfg.scenes, "val", cfg.profile.n_val, cfg.profile.image_size, seed)


def _clean_net(cfg: R.RunConfig, seed: int, scenes) -> torch.nn.Module | None:
    if not R.has_labels(scenes):
        return None
    return pretrain_utility(cfg.profile, seed, cfg.device, cfg.cache_dir, R.training_scenes(cfg.scenes),
                            progress=False)


def _lens(cfg: R.RunConfig, name: str, seed: int) -> lenses.Lens:
    return lenses.load(name, profile=cfg.profile, seed=seed, device=cfg.device, cache_dir=cfg.cache_dir,
                       scenes=R.training_scenes(cfg.scenes)).to(cfg.device)


def _base_config(cfg: R.RunConfig, lens: lenses.Lens, seed: int) -> dict:
    return {"lens": lens.current_spec().to_dict(), "profile": cfg.profile.to_dict(), "scenes": cfg.scenes,
            "seed": seed}


def _clean_utility(task: Task, cfg: R.RunConfig, _: Path) -> TaskResult:
    _clean_net(cfg, task.seed, _scenes(cfg, task.seed))
    return TaskResult()


def _spectrum(task: Task, cfg: R.RunConfig, _: Path) -> TaskResult:
    cached_plate_spectrum(cfg.cache_dir, cfg.profile.bound_scenes, seed=task.seed)
    return TaskResult()


def _sharp(task: Task, cfg: R.RunConfig, _: Path) -> TaskResult:
    scenes = _scenes(cfg, task.seed)
    rows, plates = R.sharp_reference(task.seed, cfg, R.to_tensor(scenes), scenes, _readers(task.attack),
                                     provenance(cfg.device), _clean_net(cfg, task.seed, scenes))
    return TaskResult(rows, plates)


def _lens_task(task: Task, cfg: R.RunConfig, _: Path) -> TaskResult:
    t0 = time.perf_counter()
    lens = _lens(cfg, task.lens, task.seed)
    fit_s = time.perf_counter() - t0
    sharp = R.to_tensor(_scenes(cfg, task.seed))
    t0 = time.perf_counter()
    R.sense(lens, sharp, cfg.profile.batch_size, task.seed, cfg.device)
    speed = sharp.shape[0] / (time.perf_counter() - t0)
    metrics = {"images_per_s": speed, "fit_s": fit_s, "psf_size_px": lens.geometry.psf_size_px,
               "psf_energy": float(lens.psf_and_energy()[1].min())}
    row = R.make_row(task.lens, "lens", task.seed, cfg, metrics, {**_base_config(cfg, lens, task.seed), "attack": "lens"},
                     provenance(cfg.device))
    spec = lens.current_spec()
    return TaskResult([row], meta={"coefficients_um": list(spec.mask.zernike_um), "spec": spec.to_dict()})


def _utility(task: Task, cfg: R.RunConfig, _: Path) -> TaskResult:
    scenes = _scenes(cfg, task.seed)
    if not R.has_labels(scenes):
        return TaskResult()
    lens = _lens(cfg, task.lens, task.seed)
    net, fit_s = R.utility_net_for(lens, task.lens, task.seed, cfg)
    sensor = R.sense(lens, R.to_tensor(scenes), cfg.profile.batch_size, task.seed, cfg.device)
    metrics = {**R.utility_metrics(net, sensor, scenes, cfg), "fit_s": fit_s}
    return TaskResult([R.make_row(task.lens, "utility", task.seed, cfg, metrics,
                                  {**_base_config(cfg, lens, task.seed), "attack": "utility"}, provenance(cfg.device))])


def _bound(task: Task, cfg: R.RunConfig, _: Path) -> TaskResult:
    lens = _lens(cfg, task.lens, task.seed)
    spectrum = cached_plate_spectrum(cfg.cache_dir, cfg.profile.bound_scenes, seed=task.seed)
    config = {**_base_config(cfg, lens, task.seed), "attack": "bound", "plate_format": cfg.plate_format,
              "frames": cfg.frames}
    curve = bound_curve(lens, spectrum, BOUND_CURVE_WIDTHS_PX, plate_entropy_bits(cfg.plate_format))
    return TaskResult([R.make_row(task.lens, "bound", task.seed, cfg, R.bound_metrics(lens, spectrum, cfg), config,
                                  provenance(cfg.device))],
                      meta={"curve": {k: [float(x) for x in v] for k, v in curve.items()}})


def _fit(task: Task, cfg: R.RunConfig, _: Path) -> TaskResult:
    lens = _lens(cfg, task.lens, task.seed)
    attacker = attacks.load(task.attack)
    ctx = R.fit_context(lens, cfg, task.seed, None)
    reason = attacker.skip_reason(ctx)
    if reason:
        return TaskResult(meta={"skipped": reason})
    t0 = time.perf_counter()
    attacker.fit(ctx)
    return TaskResult(meta={"fit_s": time.perf_counter() - t0})


def _evaluate(task: Task, cfg: R.RunConfig, staging: Path) -> TaskResult:
    restorer_names, reader_names = task.attack.split("|")
    restorers = [attacks.load(n) for n in restorer_names.strip(",").split(",") if n]
    directory = staging.parent
    fit_s = {}
    for r in restorers:
        done = load_result(directory, Task("fit", task.seed, task.lens, r.name))
        if done is not None and "skipped" not in done.meta:
            fit_s[r.name] = done.meta["fit_s"]
    scenes = _scenes(cfg, task.seed)
    clean = _clean_net(cfg, task.seed, scenes)
    rows, plates, pictures = R.evaluate_lens(task.lens, _lens(cfg, task.lens, task.seed), task.seed, cfg, scenes,
                                             [r for r in restorers if r.name in fit_s], _readers(reader_names),
                                             provenance(cfg.device), clean, fit_s, staging)
    return TaskResult(rows, plates, meta={"pictures": pictures})


def _readers(names: str) -> list[attacks.Reader]:
    out = [attacks.load(n) for n in names.strip(",").split(",") if n]
    return [r for r in out if isinstance(r, attacks.Reader)]


_KINDS = {"clean-utility": _clean_utility, "spectrum": _spectrum, "sharp": _sharp, "lens": _lens_task,
          "utility": _utility, "bound": _bound, "fit": _fit, "evaluate": _evaluate}
