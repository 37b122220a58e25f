"""The benchmark runner: scenes -> lens -> sensor images -> attackers -> rows.

One row per lens x attack chain x seed. The runner, not the attacker, computes every metric, so
all attackers are scored the same way. Every reader runs on the sensor image and on every
restorer's output (the chained attack: deblur, then read).
"""

from __future__ import annotations

import logging
import time
from collections.abc import Callable, Iterator
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
import torch
from tqdm.auto import tqdm

import attacks
import lenses
from benchmark.cache import cache_root, config_hash
from benchmark.metrics import finite_mean, psnr, ssim
from benchmark.charts.plate_gallery import write_plate_gallery
from benchmark.plate_scoring import PlateOutcome, readable, score_scene, summarise
from benchmark.profiles import Profile
from benchmark.charts.samples import write_sample_grid
from benchmark.scenes import CLASS_NAMES, PLATE_FORMAT, Scene, load_scenes, plate_entropy_bits
from lenses.bound import PlateSpectrum, bound_row
from benchmark.utility.scoring import confusion_matrix, predict, scores, window_for
from lenses.codesign.schemes import SCHEMES
from lenses.codesign.trainer import CoDesign

log = logging.getLogger(__name__)


@dataclass
class RunConfig:
    lenses: list[str]
    attacks: list[str] | None  # None: every registered attacker
    scenes: str
    profile: Profile
    seeds: list[int]
    device: str = "cpu"
    cache_dir: Path = field(default_factory=cache_root)
    plate_format: str = PLATE_FORMAT   # the plate strings the bound's entropy counts
    frames: int = 30                   # T of the video bound (T = 1 is always reported)


def to_tensor(scenes: list[Scene]) -> torch.Tensor:
    """Scene images -> (N,3,H,W) float32 in [0,1]."""
    return torch.from_numpy(np.stack([s.image for s in scenes])).permute(0, 3, 1, 2).contiguous()


def batches(x: torch.Tensor, size: int) -> Iterator[torch.Tensor]:
    for i in range(0, x.shape[0], size):
        yield x[i:i + size]


def sense(lens: lenses.Lens, sharp: torch.Tensor, batch_size: int, seed: int, device: str) -> torch.Tensor:
    """Sensor images of `sharp` through `lens`, noise drawn from a generator seeded with `seed`."""
    gen = torch.Generator(device=device).manual_seed(seed)
    with torch.no_grad():
        return torch.cat([lens(b.to(device), generator=gen).cpu() for b in batches(sharp, batch_size)])


def train_pairs_factory(lens: lenses.Lens, cfg: RunConfig, seed: int) -> Callable[[], Iterator[tuple[torch.Tensor, torch.Tensor]]]:
    """A re-iterable source of (sensor, sharp) crops from the TRAIN split, for attackers that fit."""
    p = cfg.profile
    cached: list[torch.Tensor] = []

    def pairs() -> Iterator[tuple[torch.Tensor, torch.Tensor]]:
        if not cached:
            cached.append(to_tensor(load_scenes(cfg.scenes, "train", p.n_train, p.image_size, seed)))
        sharp_all = cached[0]
        rng = np.random.default_rng([seed, 1])
        gen = torch.Generator(device=cfg.device).manual_seed(seed + 1)
        h, w = p.train_crop
        for start in range(0, sharp_all.shape[0], p.batch_size):
            crops = []
            for img in sharp_all[start:start + p.batch_size]:
                y = int(rng.integers(0, img.shape[1] - h + 1))
                x = int(rng.integers(0, img.shape[2] - w + 1))
                crops.append(img[:, y:y + h, x:x + w])
            sharp = torch.stack(crops).to(cfg.device)
            with torch.no_grad():
                yield lens(sharp, generator=gen), sharp

    return pairs


def training_scenes(scene_set: str) -> str:
    """Scenes that carry labels for training: Cityscapes when given, else the synthetic set."""
    return scene_set if scene_set.startswith("cityscapes:") else "synthetic"


def has_labels(scenes: list[Scene]) -> bool:
    return any(bool((s.labels != 255).any()) for s in scenes)


def segmenter(net: torch.nn.Module, cfg: RunConfig) -> Callable[[torch.Tensor], torch.Tensor]:
    """images (B,3,H,W) in [0,1] -> train ids (B,H,W), by sliding-window inference."""
    window, stride = window_for(cfg.profile.image_size, cfg.profile.train_crop)
    return lambda images: predict(net, images, window, stride, cfg.profile.batch_size, cfg.device).to(images.device)


def utility_metrics(net: torch.nn.Module, images: torch.Tensor, scenes: list[Scene], cfg: RunConfig) -> dict:
    """miou / mean_acc / overall_acc (+ per-class IoU columns) and inference speed on a split."""
    t0 = time.perf_counter()
    pred = segmenter(net, cfg)(images)
    speed = images.shape[0] / (time.perf_counter() - t0)
    target = torch.from_numpy(np.stack([s.labels for s in scenes]))
    s = scores(confusion_matrix(pred, target))
    metrics = {k: s[k] for k in ("miou", "mean_acc", "overall_acc")}
    metrics.update({f"iou_{name}": v for name, v in zip(CLASS_NAMES, s["class_iou"])})
    metrics["images_per_s"] = speed
    return metrics


def utility_net_for(lens: lenses.Lens, lens_name: str, seed: int, cfg: RunConfig) -> tuple[torch.nn.Module, float]:
    """The lens's own utility network and the seconds spent training it now (0 when cached).

    Co-designed lenses bring theirs; a fixed lens gets the clean net fine-tuned to its sensor
    images (scheme `fixed`), cached like any training run.
    """
    if lens.utility_net is not None:
        return lens.utility_net, 0.0
    run = CoDesign(lens.spec, SCHEMES["fixed"], cfg.profile, seed, cfg.device, cfg.cache_dir,
                   name=f"fixed-{lens_name.replace('/', '_')}", scene_set=training_scenes(cfg.scenes))
    t0 = time.perf_counter()
    trained = run.load_or_train()
    return trained.utility_net, time.perf_counter() - t0


def make_row(lens_name: str, attack: str, seed: int, cfg: RunConfig, metrics: dict, config: dict, prov: dict) -> dict:
    row = {"lens": lens_name, "attack": attack, "seed": seed, "profile": cfg.profile.name, "scenes": cfg.scenes}
    row.update(metrics)
    row["config_hash"] = config_hash(config)
    row.update(prov)
    return row


def restoration_metrics(restored: torch.Tensor, sharp: torch.Tensor) -> dict:
    return {"psnr_db": finite_mean(psnr(restored, sharp)), "ssim": finite_mean(ssim(restored, sharp)),
            "n_images": int(sharp.shape[0])}


def read_plates(reader: attacks.Reader, images: torch.Tensor, scenes: list[Scene], batch_size: int,
                device: str, segment: Callable[[torch.Tensor], torch.Tensor] | None = None
                ) -> tuple[list[PlateOutcome], dict[str, float], list[list[attacks.PlateRead]]]:
    """Run a reader over images (batch-wise) and score it against the scenes' plates.

    Returns the per-plate outcomes, the timing (``images_per_s``, and ``<stage>_s_per_image`` for
    readers that keep ``stage_seconds``, like lpdr) and the reads per image.
    """
    outcomes: list[PlateOutcome] = []
    all_reads: list[list[attacks.PlateRead]] = []
    stages_before = dict(getattr(reader, "stage_seconds", {}))
    t0 = time.perf_counter()
    for start in range(0, images.shape[0], batch_size):
        chunk = scenes[start:start + batch_size]
        hints = attacks.ReadHints(vehicle_boxes=[[v.box_xyxy for v in s.vehicles] for s in chunk], segment=segment)
        with torch.no_grad():
            reads = reader.read(images[start:start + batch_size].to(device), hints)
        for r, scene in zip(reads, chunk):
            outcomes.extend(score_scene(r, scene))
        all_reads.extend(reads)
    timing = {"images_per_s": images.shape[0] / (time.perf_counter() - t0)}
    for stage, seconds in getattr(reader, "stage_seconds", {}).items():
        timing[f"{stage}_s_per_image"] = (seconds - stages_before.get(stage, 0.0)) / images.shape[0]
    return outcomes, timing, all_reads


def plate_rows(lens_name: str, attack: str, seed: int, cfg: RunConfig, outcomes: list[PlateOutcome],
               timing: dict[str, float], reader: attacks.Reader, config: dict, prov: dict) -> tuple[dict, list[dict]]:
    """The row of one reader chain, and its per-plate records (for charts and galleries)."""
    metrics = {"threat_model": reader.threat_model.value, **summarise(outcomes), **timing}
    row = make_row(lens_name, attack, seed, cfg, metrics, {**config, "attack": attack, "reader": reader.describe()}, prov)
    records = [{"lens": lens_name, "attack": attack, "seed": seed, **o.__dict__} for o in outcomes]
    return row, records


def bound_metrics(lens: lenses.Lens, spectrum: PlateSpectrum, cfg: RunConfig) -> dict:
    t0 = time.perf_counter()
    metrics = bound_row(lens, spectrum, plate_entropy_bits(cfg.plate_format), frames=tuple(sorted({1, cfg.frames})))
    metrics["bound_plate_format"] = cfg.plate_format
    metrics["fit_s"] = time.perf_counter() - t0
    return metrics


def fit_context(lens: lenses.Lens, cfg: RunConfig, seed: int,
                lens_net: torch.nn.Module | None) -> attacks.FitContext:
    """What an attacker of this lens may use: the lens, training pairs, cache, device, seed, profile."""
    return attacks.FitContext(lens=lens, train_pairs=train_pairs_factory(lens, cfg, seed),
                              cache_dir=cfg.cache_dir / "attacks", device=cfg.device, seed=seed, profile=cfg.profile,
                              extras={"segmenter": segmenter(lens_net, cfg) if lens_net is not None else None})


def evaluate_lens(lens_name: str, lens: lenses.Lens, seed: int, cfg: RunConfig, scenes: list[Scene],
                  restorers: list[attacks.Restorer], readers: list[attacks.Reader], prov: dict,
                  clean_net: torch.nn.Module | None, fit_s: dict[str, float], out_dir: Path
                  ) -> tuple[list[dict], list[dict], list[str]]:
    """Every restorer and every reader chain on one lens and seed; sample pictures into `out_dir`.

    Restorers were fitted by their own tasks (`fit_s` their times); fitting again here is a cache hit.
    Returns the rows, the per-plate records and the picture file names.
    """
    p = cfg.profile
    sharp = to_tensor(scenes)
    sensor = sense(lens, sharp, p.batch_size, seed, cfg.device)
    base_config = {"lens": lens.current_spec().to_dict(), "profile": p.to_dict(), "scenes": cfg.scenes, "seed": seed}
    lens_net = utility_net_for(lens, lens_name, seed, cfg)[0] if clean_net is not None else None
    ctx = fit_context(lens, cfg, seed, lens_net)
    rows: list[dict] = []
    restored: dict[str, torch.Tensor] = {}
    for attacker in tqdm(restorers, desc=f"{lens_name} restorers", leave=False):
        attacker.fit(ctx)
        t0 = time.perf_counter()
        with torch.no_grad():
            out = torch.cat([attacker.restore(b.to(cfg.device)).cpu() for b in batches(sensor, p.batch_size)])
        run_s = time.perf_counter() - t0
        restored[attacker.name] = out
        metrics = restoration_metrics(out, sharp)
        metrics.update({"threat_model": attacker.threat_model.value, "fit_s": fit_s[attacker.name],
                        "images_per_s": sharp.shape[0] / run_s})
        rows.append(make_row(lens_name, attacker.name, seed, cfg, metrics,
                             {**base_config, "attack": attacker.describe()}, prov))
    plates: list[dict] = []
    pictures = []
    for reader in readers:
        reason = reader.skip_reason(ctx)
        if reason:
            log.info("%s on %s skipped: %s", reader.name, lens_name, reason)
            continue
        reader.fit(ctx)
        sources = {reader.name: sensor, **{f"{name}>{reader.name}": out for name, out in restored.items()}}
        source_reads = {}
        for chain, images in tqdm(sources.items(), desc=f"{lens_name} {reader.name}", leave=False):
            # The attacker with device access segments sensor images with the lens's own network,
            # restored images with the clean one.
            net = lens_net if chain == reader.name else clean_net
            segment = segmenter(net, cfg) if net is not None else None
            outcomes, timing, source_reads[chain] = read_plates(reader, images, scenes, p.batch_size, cfg.device,
                                                               segment)
            row, records = plate_rows(lens_name, chain, seed, cfg, outcomes, timing, reader, base_config, prov)
            rows.append(row)
            plates.extend(records)
        gallery = f"plates_{lens_name}_{reader.name}_seed{seed}.png".replace("/", "_")
        images = {"sharp": sharp, "sensor": sensor, **restored}
        reads = {"sensor": source_reads[reader.name],
                 **{name: source_reads[f"{name}>{reader.name}"] for name in restored}}
        if any(readable(pl) for s in scenes for pl in s.plates):
            write_plate_gallery(images, scenes, reads, out_dir / gallery)
            pictures.append(gallery)
    scores = {r["attack"]: f"PSNR {r['psnr_db']:.2f} dB, SSIM {r['ssim']:.3f}" for r in rows if "psnr_db" in r}
    as_hwc = lambda t: t[0].permute(1, 2, 0).clamp(0, 1).numpy()  # noqa: E731
    name = f"samples_{lens_name}_seed{seed}.png".replace("/", "_")
    write_sample_grid(out_dir / name, lens_name, lens.psf().detach().cpu().numpy(), as_hwc(sharp), as_hwc(sensor),
                      {k: as_hwc(v) for k, v in restored.items()}, scores)
    return rows, plates, [name, *pictures]


def sharp_reference(seed: int, cfg: RunConfig, sharp: torch.Tensor, scenes: list[Scene],
                    readers: list[attacks.Reader], prov: dict, clean_net: torch.nn.Module | None
                    ) -> tuple[list[dict], list[dict]]:
    """Rows measured on the sharp scenes themselves (lens `sharp`, the paper's "Original"):
    the clean utility net's scores and every reader."""
    rows, plates = [], []
    config = {"lens": "sharp", "profile": cfg.profile.to_dict(), "scenes": cfg.scenes, "seed": seed}
    segment = segmenter(clean_net, cfg) if clean_net is not None else None
    if clean_net is not None:
        rows.append(make_row("sharp", "utility", seed, cfg, utility_metrics(clean_net, sharp, scenes, cfg),
                             {**config, "attack": "utility"}, prov))
    ctx = attacks.FitContext(cache_dir=cfg.cache_dir / "attacks", device=cfg.device, seed=seed, profile=cfg.profile,
                             extras={"segmenter": segment})
    for reader in readers:
        if reader.skip_reason(ctx):
            continue
        reader.fit(ctx)
        outcomes, timing, _ = read_plates(reader, sharp, scenes, cfg.profile.batch_size, cfg.device, segment)
        row, records = plate_rows("sharp", reader.name, seed, cfg, outcomes, timing, reader, config, prov)
        rows.append(row)
        plates.extend(records)
    return rows, plates


@dataclass
class RunOutput:
    rows: list[dict]
    plates: list[dict]
    pictures: list[Path]                 # sample images written by the tasks
    lens_info: dict[str, dict]           # per lens: learned coefficients and spec
    bound_curves: dict[str, tuple]       # per lens: (plate widths px, Fano ceiling) of the first seed


def run(cfg: RunConfig, executor: str = "local") -> RunOutput:
    """Plan the run's tasks, execute them (locally or on Ray), and collect rows in plan order."""
    from benchmark import executors, tasks
    selected, failures = attacks.load_all(cfg.attacks)
    for f in failures:
        log.warning("attacker plugin %r failed to load and is skipped: %s", f.name, f.error)
    if cfg.attacks is None:
        selected = [a for a in selected if a.run_by_default]
    restorers = [a.name if cfg.attacks is None else _spec_for(a, cfg.attacks) for a in selected
                 if isinstance(a, attacks.Restorer)]
    readers = [a.name if cfg.attacks is None else _spec_for(a, cfg.attacks) for a in selected
               if isinstance(a, attacks.Reader)]
    planned = tasks.plan(cfg, restorers, readers)
    directory = tasks.run_directory(cfg)
    results = executors.get(executor).run(planned, cfg, directory)
    out = RunOutput([], [], [], {}, {})
    for task in planned:
        result = results[task.key]
        out.rows.extend(result.rows)
        out.plates.extend(result.plates)
        out.pictures.extend(directory / task.key / name for name in result.meta.get("pictures", []))
        if task.kind == "lens" and task.lens not in out.lens_info:
            out.lens_info[task.lens] = {k: result.meta[k] for k in ("coefficients_um", "spec")}
        if task.kind == "bound" and task.lens not in out.bound_curves:
            curve = result.meta["curve"]
            out.bound_curves[task.lens] = (curve["width_px"], curve["ceiling"])
    return out


def _spec_for(attacker: attacks.Attack, requested: list[str]) -> str:
    """The spec the user gave for this attacker (a name or a file path), so that tasks can reload it."""
    for spec in requested:
        if spec == attacker.name or (spec.endswith(f":{type(attacker).__name__}") and ".py:" in spec):
            return spec
    return attacker.name
