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
from benchmark.plates import PlateOutcome, score_scene, summarise
from benchmark.profiles import Profile
from benchmark.provenance import provenance
from benchmark.plate_spectrum import cached_plate_spectrum
from benchmark.scenes import CLASS_NAMES, PLATE_FORMAT, Scene, load_scenes, plate_entropy_bits
from lenses.bound import PlateSpectrum, bound_row
from benchmark.utility.scoring import confusion_matrix, predict, scores, window_for
from lenses.codesign.schemes import SCHEMES
from lenses.codesign.trainer import CoDesign, pretrain_utility

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


@dataclass
class LensOutcome:
    """What one lens produced for one seed: rows plus the images the report draws."""

    lens: lenses.Lens
    rows: list[dict]
    scene: np.ndarray
    sensor: np.ndarray
    restored: dict[str, np.ndarray]
    plates: list[dict] = field(default_factory=list)  # one record per (chain, readable plate)


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


def _row(lens_name: str, attack: str, seed: int, cfg: RunConfig, metrics: dict, config: dict, prov: dict) -> dict:
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
                ) -> tuple[list[PlateOutcome], float]:
    """Run a reader over images (batch-wise) and score it against the scenes' plates.

    Returns the per-plate outcomes and the reader's images per second.
    """
    outcomes: list[PlateOutcome] = []
    t0 = time.perf_counter()
    for start in range(0, images.shape[0], batch_size):
        chunk = scenes[start:start + batch_size]
        hints = attacks.ReadHints(vehicle_boxes=[[v.box_xyxy for v in s.vehicles] for s in chunk], segment=segment)
        with torch.no_grad():
            reads = reader.read(images[start:start + batch_size].to(device), hints)
        for r, scene in zip(reads, chunk):
            outcomes.extend(score_scene(r, scene))
    return outcomes, images.shape[0] / (time.perf_counter() - t0)


def plate_rows(lens_name: str, attack: str, seed: int, cfg: RunConfig, outcomes: list[PlateOutcome],
               speed: float, reader: attacks.Reader, config: dict, prov: dict) -> tuple[dict, list[dict]]:
    """The row of one reader chain, and its per-plate records (for charts and galleries)."""
    metrics = {"threat_model": reader.threat_model.value, **summarise(outcomes), "images_per_s": speed}
    row = _row(lens_name, attack, seed, cfg, metrics, {**config, "attack": attack, "reader": reader.describe()}, prov)
    records = [{"lens": lens_name, "attack": attack, "seed": seed, **o.__dict__} for o in outcomes]
    return row, records


def bound_metrics(lens: lenses.Lens, spectrum: PlateSpectrum, cfg: RunConfig) -> dict:
    t0 = time.perf_counter()
    metrics = bound_row(lens, spectrum, plate_entropy_bits(cfg.plate_format), frames=tuple(sorted({1, cfg.frames})))
    metrics["bound_plate_format"] = cfg.plate_format
    metrics["fit_s"] = time.perf_counter() - t0
    return metrics


def run_lens(lens_name: str, seed: int, cfg: RunConfig, sharp: torch.Tensor, scenes: list[Scene],
             attackers: list[attacks.Attack], prov: dict, clean_net: torch.nn.Module | None,
             spectrum: PlateSpectrum | None = None) -> LensOutcome:
    """Everything for one lens and one seed."""
    p = cfg.profile
    t0 = time.perf_counter()
    lens = lenses.load(lens_name, profile=p, seed=seed, device=cfg.device, cache_dir=cfg.cache_dir,
                       scenes=training_scenes(cfg.scenes)).to(cfg.device)
    lens_fit_s = time.perf_counter() - t0
    base_config = {"lens": lens.current_spec().to_dict(), "profile": p.to_dict(), "scenes": cfg.scenes, "seed": seed}
    t0 = time.perf_counter()
    sensor = sense(lens, sharp, p.batch_size, seed, cfg.device)
    lens_s = time.perf_counter() - t0
    rows = [_row(lens_name, "lens", seed, cfg,
                 {"images_per_s": sharp.shape[0] / lens_s, "psf_size_px": lens.geometry.psf_size_px,
                  "psf_energy": float(lens.psf_and_energy()[1].min())},
                 {**base_config, "attack": "lens"}, prov)]
    if spectrum is not None:
        rows.append(_row(lens_name, "bound", seed, cfg, bound_metrics(lens, spectrum, cfg),
                         {**base_config, "attack": "bound", "plate_format": cfg.plate_format,
                          "frames": cfg.frames}, prov))
    lens_net = None
    if clean_net is not None:
        lens_net, utility_fit_s = utility_net_for(lens, lens_name, seed, cfg)
        metrics = {**utility_metrics(lens_net, sensor, scenes, cfg), "fit_s": lens_fit_s + utility_fit_s}
        rows.append(_row(lens_name, "utility", seed, cfg, metrics, {**base_config, "attack": "utility"}, prov))
    ctx = attacks.FitContext(lens=lens, train_pairs=train_pairs_factory(lens, cfg, seed),
                             cache_dir=cfg.cache_dir / "attacks", device=cfg.device, seed=seed, profile=p,
                             extras={"segmenter": segmenter(lens_net, cfg) if lens_net is not None else None})
    restored: dict[str, torch.Tensor] = {}
    for attacker in tqdm([a for a in attackers if isinstance(a, attacks.Restorer)], desc=f"{lens_name} restorers",
                         leave=False):
        reason = attacker.skip_reason(ctx)
        if reason:
            log.info("%s on %s skipped: %s", attacker.name, lens_name, reason)
            continue
        t0 = time.perf_counter()
        attacker.fit(ctx)
        fit_s = time.perf_counter() - t0
        t0 = time.perf_counter()
        with torch.no_grad():
            out = torch.cat([attacker.restore(b.to(cfg.device)).cpu() for b in batches(sensor, p.batch_size)])
        run_s = time.perf_counter() - t0
        restored[attacker.name] = out
        metrics = restoration_metrics(out, sharp)
        metrics.update({"threat_model": attacker.threat_model.value, "fit_s": fit_s,
                        "images_per_s": sharp.shape[0] / run_s})
        rows.append(_row(lens_name, attacker.name, seed, cfg, metrics,
                         {**base_config, "attack": attacker.describe()}, prov))
    plates: list[dict] = []
    for reader in [a for a in attackers if isinstance(a, attacks.Reader)]:
        reason = reader.skip_reason(ctx)
        if reason:
            log.info("%s on %s skipped: %s", reader.name, lens_name, reason)
            continue
        reader.fit(ctx)
        sources = {reader.name: sensor, **{f"{name}>{reader.name}": out for name, out in restored.items()}}
        for chain, images in tqdm(sources.items(), desc=f"{lens_name} {reader.name}", leave=False):
            # The attacker with device access segments sensor images with the lens's own network,
            # restored images with the clean one.
            net = lens_net if chain == reader.name else clean_net
            segment = segmenter(net, cfg) if net is not None else None
            outcomes, speed = read_plates(reader, images, scenes, p.batch_size, cfg.device, segment)
            row, records = plate_rows(lens_name, chain, seed, cfg, outcomes, speed, reader, base_config, prov)
            rows.append(row)
            plates.extend(records)
    as_hwc = lambda t: t[0].permute(1, 2, 0).clamp(0, 1).numpy()  # noqa: E731
    return LensOutcome(lens, rows, as_hwc(sharp), as_hwc(sensor), {k: as_hwc(v) for k, v in restored.items()},
                       plates)


def sharp_reference(seed: int, cfg: RunConfig, sharp: torch.Tensor, scenes: list[Scene],
                    attackers: list[attacks.Attack], prov: dict, clean_net: torch.nn.Module | None
                    ) -> tuple[list[dict], list[dict]]:
    """Rows measured on the sharp scenes themselves (lens `sharp`, the paper's "Original"):
    the clean utility net's scores and every reader."""
    rows, plates = [], []
    config = {"lens": "sharp", "profile": cfg.profile.to_dict(), "scenes": cfg.scenes, "seed": seed}
    segment = segmenter(clean_net, cfg) if clean_net is not None else None
    if clean_net is not None:
        rows.append(_row("sharp", "utility", seed, cfg, utility_metrics(clean_net, sharp, scenes, cfg),
                         {**config, "attack": "utility"}, prov))
    ctx = attacks.FitContext(cache_dir=cfg.cache_dir / "attacks", device=cfg.device, seed=seed, profile=cfg.profile,
                             extras={"segmenter": segment})
    for reader in [a for a in attackers if isinstance(a, attacks.Reader)]:
        if reader.skip_reason(ctx):
            continue
        reader.fit(ctx)
        outcomes, speed = read_plates(reader, sharp, scenes, cfg.profile.batch_size, cfg.device, segment)
        row, records = plate_rows("sharp", reader.name, seed, cfg, outcomes, speed, reader, config, prov)
        rows.append(row)
        plates.extend(records)
    return rows, plates


def run(cfg: RunConfig, on_lens: Callable[[LensOutcome, int], None] | None = None) -> tuple[list[dict], list[dict]]:
    """All rows of a run and the per-plate records of every reader chain.

    `on_lens(outcome, seed)` is called after each lens (for pictures).
    """
    selected, failures = attacks.load_all(cfg.attacks)
    for f in failures:
        log.warning("attacker plugin %r failed to load and is skipped: %s", f.name, f.error)
    prov = provenance(cfg.device)
    rows: list[dict] = []
    plates: list[dict] = []
    for seed in cfg.seeds:
        torch.manual_seed(seed)
        scenes = load_scenes(cfg.scenes, "val", cfg.profile.n_val, cfg.profile.image_size, seed)
        sharp = to_tensor(scenes)
        t0 = time.perf_counter()
        clean_net = None
        if has_labels(scenes):
            clean_net = pretrain_utility(cfg.profile, seed, cfg.device, cfg.cache_dir, training_scenes(cfg.scenes))
        spectrum = cached_plate_spectrum(cfg.cache_dir, cfg.profile.bound_scenes, seed=seed)
        ref_rows, ref_plates = sharp_reference(seed, cfg, sharp, scenes, selected, prov, clean_net)
        for r in ref_rows:
            r["wall_s"] = time.perf_counter() - t0
        rows.extend(ref_rows)
        plates.extend(ref_plates)
        for lens_name in tqdm(cfg.lenses, desc=f"seed {seed}: lenses"):
            t0 = time.perf_counter()
            outcome = run_lens(lens_name, seed, cfg, sharp, scenes, selected, prov, clean_net, spectrum)
            wall = time.perf_counter() - t0
            for r in outcome.rows:
                r["wall_s"] = wall
            rows.extend(outcome.rows)
            plates.extend(outcome.plates)
            if on_lens is not None:
                on_lens(outcome, seed)
    return rows, plates
