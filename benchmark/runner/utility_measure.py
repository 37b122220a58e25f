"""Utility of a lens: its segmentation network and how well it segments the sensor images."""

from __future__ import annotations

import time

import numpy as np
import torch

import lenses
from benchmark.codesign.schemes import SCHEMES
from benchmark.codesign.trainer import CoDesign
from benchmark.runner.config import RunConfig, training_scenes
from benchmark.scenes import CLASS_NAMES, Scene
from benchmark.codesign.utility.scoring import confusion_matrix, predict, scores, window_for
from benchmark.codesign.utility.segformer_onnx import segformer_engine


def has_labels(scenes: list[Scene]) -> bool:
    """True when any scene carries segmentation labels (255 = ignore everywhere means none)."""
    return any(bool((s.labels != 255).any()) for s in scenes)


class Segmenter:
    """images (B,3,H,W) in [0,1] -> train ids (B,H,W), by sliding-window inference of ``net``.

    The windows run through ``segformer_engine`` (ONNX Runtime on the CPU, torch elsewhere or if the
    export fails); ``describe()`` says which, for the row that reports the scores. Given a ``lens``,
    its sensor images are white-balanced first (``Lens.white_balance``), as its network was trained.
    """

    def __init__(self, net: torch.nn.Module, cfg: RunConfig, lens: lenses.Lens | None = None) -> None:
        self.net, self.cfg, self.lens = net, cfg, lens
        self.window, self.stride = window_for(cfg.profile.image_size, cfg.profile.train_crop)
        self.engine = segformer_engine(net.eval(), cfg.cache_dir, self.window)

    def __call__(self, images: torch.Tensor) -> torch.Tensor:
        if self.lens is not None:
            images = self.lens.white_balance(images)
        return predict(self.net, images, self.window, self.stride, self.cfg.profile.batch_size, self.cfg.device,
                       logits=self.engine).to(images.device)

    def describe(self) -> dict[str, object]:
        """The inference backend in use (``InferenceEngine.describe``) and the input it is given."""
        balance = "divide-by-known-sensor-gain" if self.lens is not None else "none"
        return {**self.engine.describe(), "white_balance": balance}


def segmenter(net: torch.nn.Module, cfg: RunConfig, lens: lenses.Lens | None = None) -> Segmenter:
    """images (B,3,H,W) in [0,1] -> train ids (B,H,W), by sliding-window inference (`Segmenter`);
    a lens's sensor images are white-balanced first (pass the `lens`)."""
    return Segmenter(net, cfg, lens)


def utility_metrics(net: torch.nn.Module, images: torch.Tensor, scenes: list[Scene], cfg: RunConfig,
                    lens: lenses.Lens | None = None) -> dict[str, float]:
    """miou / mean_acc / overall_acc (+ per-class IoU columns) and images_per_s (`utility_scores`)."""
    return utility_scores(net, images, scenes, cfg, lens)[0]


def utility_scores(net: torch.nn.Module, images: torch.Tensor, scenes: list[Scene], cfg: RunConfig,
                   lens: lenses.Lens | None = None) -> tuple[dict[str, float], torch.Tensor]:
    """miou / mean_acc / overall_acc (+ per-class IoU columns) and inference speed (images_per_s)
    of `net` on images (N,3,H,W) (a `lens`'s sensor images: white-balanced first), and the per-scene
    confusion matrices (N, C, C) (for intervals)."""
    segment = segmenter(net, cfg, lens)  # exporting the graph (once per weights) is not inference time
    t0 = time.perf_counter()
    pred = segment(images)
    speed = images.shape[0] / (time.perf_counter() - t0)
    target = torch.from_numpy(np.stack([s.labels for s in scenes]))
    per_scene = torch.stack([confusion_matrix(p[None], t[None]) for p, t in zip(pred, target)])
    s = scores(per_scene.sum(dim=0))
    metrics = {k: float(s[k]) for k in ("miou", "mean_acc", "overall_acc")}  # type: ignore[arg-type]
    metrics.update({f"iou_{name}": float(v) for name, v in zip(CLASS_NAMES, s["class_iou"])  # type: ignore[call-overload]
                    if np.isfinite(v)})
    metrics["images_per_s"] = speed
    return metrics, per_scene


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
