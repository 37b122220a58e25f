"""Training of the learned plate reader (``learned-reader``): budgets, held-out curve, early stop.

Recipe: cross-entropy per character slot (label smoothing 0.05), AdamW (weight decay 1e-4) warmed up
over the first tenth of the budget's steps to ``lr``, then a cosine decay, batches of simulated plates
(``attacks.readers.plates.plate_sim``). A batch is ``bands_per_batch`` equal parts, part k drawn from the k-th
of as many log-spaced bands of the budget's width range (one camera call per part, its width drawn
log-uniform in its band). Batches of one band each (``bands_per_batch=1``, the pre-training's recipe)
made a fine-tune on a blurring lens swing: most bands are unreadable there (on gp everything under
64 px), so most steps pulled the reader toward guessing and away from the wide plates it could read.
On the quick gp lens (seed 0, lr 1e-3) the held-out mean went 0.17, 0.14, 0.17, ... 0.19 at step 600,
then 0.07-0.14 (192 px plates 0.84 -> 0.06 -> 0.34), also at lr 3e-4 (0.20 at 600, then 0.07-0.14), and
recomputing BatchNorm's statistics over every band did not steady it; with four bands per batch it
rose steadily, 0.22 at step 100 to 0.26 at 900 (96 px 0.59, 128 px 0.97, 192 px 1.0).

Every ``eval_every`` steps the reader is scored on a fixed held-out set (plates of each width bin
of ``EVAL_WIDTHS_PX`` that fits the range, the true box, no jitter); training stops
when the mean exact-plate accuracy over the bins has not risen by ``min_gain`` over the last
``patience`` evaluations (it has flattened), never before ``min_steps``, or at the budget's last step.
The mean is diluted and noisy where a blurring lens leaves most bins at 0 (seven of ten on defocus), so a
long schedule with a floor (``min_steps``) reads more there alone; the quick per-lens budget runs one
short cycle instead, because next to ``learned-reader-psf`` that reader adds nothing the studies can tell on
the blurring lenses (``benchmark.studies.reader_schedule_study``). A fit stopped by the
budget while its last ``patience`` evaluations still gained ``min_gain`` is flagged
``still_rising``: a privacy figure from it is an upper bound on what a longer fit would leave.

The fit ends on the weights of its best held-out evaluation (``FitCurve.best_step``), not its last: on a
blurring lens the held-out accuracy is noisy and can fall after an early peak (the shipped gp fit before
this rule: 0.209 at step 600, 0.084 at its last, 800).
"""

from __future__ import annotations

import dataclasses
import logging
import math
import time
from collections.abc import Callable
from typing import Any

import numpy as np
import torch
from torch import Tensor, nn
from tqdm.auto import tqdm

from attacks.networks.plate_cnn import PlateCNN
from attacks.readers.plates.plate_sim import PlateBatch, simulate_plates

__all__ = ["EVAL_WIDTHS_PX", "FitCurve", "ReaderBudget", "flattened", "held_out_gain", "held_out_set", "optimiser", "plate_accuracy",
           "slot_loss", "train_reader", "training_batch", "width_bands"]

log = logging.getLogger(__name__)

EVAL_WIDTHS_PX: tuple[int, ...] = (8, 12, 16, 24, 32, 48, 64, 96, 128, 192)
"""Width bins (px) of the held-out curve: the bins the leaderboard scores plate accuracy in."""

Camera = Callable[[Tensor, torch.Generator], Tensor]


@dataclasses.dataclass(frozen=True)
class ReaderBudget:
    """Steps and sizes of one fit (pre-training or fine-tuning on a lens).

    Attributes:
        max_steps: Optimiser steps at most (the fit may stop earlier, when it has flattened).
        batch_size: Plates per step.
        lr: Peak learning rate of the one-cycle schedule.
        widths_px: (low, high) range of the training plates' widths, pixels.
        eval_every: Steps between held-out evaluations.
        eval_plates: Held-out plates per width bin.
        patience: Evaluations without a gain of ``min_gain`` before the fit stops.
        min_gain: The gain in mean held-out accuracy (a fraction) that counts as still improving.
        min_steps: Steps before which the fit never stops as flattened.
        bands_per_batch: Log-spaced width bands every batch draws an equal part from (module docstring).
        eval_start: Evaluate the start before the first step too, so the fit may keep it (a start that
            already reads the lens: a fine-tune that does not beat it costs its seconds and changes nothing).
    """

    max_steps: int
    batch_size: int
    lr: float
    widths_px: tuple[float, float]
    eval_every: int
    eval_plates: int
    patience: int
    min_gain: float = 0.01
    min_steps: int = 0
    bands_per_batch: int = 1
    eval_start: bool = False

    def __post_init__(self) -> None:
        if not 1 <= self.bands_per_batch <= self.batch_size:
            raise ValueError(f"ReaderBudget.bands_per_batch={self.bands_per_batch}: must be 1 to batch_size "
                             f"({self.batch_size}), each band gets at least one plate")

    def to_dict(self) -> dict[str, Any]:
        """The fields (``min_steps``, ``bands_per_batch`` and ``eval_start`` only when not their defaults:
        the keys of fits made before them stay valid)."""
        d = dataclasses.asdict(self)
        if not d["min_steps"]:
            del d["min_steps"]
        if d["bands_per_batch"] == 1:
            del d["bands_per_batch"]
        if not d["eval_start"]:
            del d["eval_start"]
        return d


@dataclasses.dataclass
class FitCurve:
    """Held-out accuracy during a fit: ``steps[i]`` -> ``accuracy[i]`` (mean over the bins) and
    ``per_width[i]`` ({width px: accuracy}); why it stopped; whether it was still rising; the step whose
    weights the fit kept (``best_step``: its best evaluation; a curve stored before that rule kept its last)."""

    steps: list[int]
    accuracy: list[float]
    per_width: list[dict[int, float]]
    stopped: str
    still_rising: bool
    seconds: float
    best_step: int = 0

    @property
    def kept(self) -> int:
        """The index of the evaluation whose weights the fit kept (-1: none evaluated)."""
        return self.steps.index(self.best_step) if self.best_step in self.steps else len(self.steps) - 1

    def to_dict(self) -> dict[str, Any]:
        return {**dataclasses.asdict(self), "per_width": [{str(k): v for k, v in d.items()} for d in self.per_width]}

    @classmethod
    def from_dict(cls, d: dict[str, Any]) -> FitCurve:
        steps = list(d["steps"])
        return cls(steps, list(d["accuracy"]), [{int(k): float(v) for k, v in p.items()} for p in d["per_width"]],
                   str(d["stopped"]), bool(d["still_rising"]), float(d["seconds"]),
                   int(d.get("best_step", steps[-1] if steps else 0)))


def held_out_set(camera: Camera | None, budget: ReaderBudget, spread_px: float, psf_half_px: int, fmt: str,
                 seed: int) -> dict[int, PlateBatch]:
    """The fixed held-out plates: ``budget.eval_plates`` per width bin of ``EVAL_WIDTHS_PX`` inside
    the budget's range, true boxes, drawn from ``seed`` (never the training draws)."""
    low, high = budget.widths_px
    rng, generator = np.random.default_rng([seed, 1]), torch.Generator().manual_seed(seed + 7919)
    # Only the crops are scored: the simulated patches (about 60 MB for quick through defocus) are not kept.
    return {w: dataclasses.replace(simulate_plates(camera, budget.eval_plates, (w, w), rng, generator, spread_px, fmt,
                                                   psf_half_px, jitter=False), images=None)
            for w in EVAL_WIDTHS_PX if low <= w <= high}


def plate_accuracy(net: nn.Module, batch: PlateBatch) -> float:
    """The share of ``batch``'s plates whose every slot ``net`` reads right (exact plate)."""
    was_training = net.training
    net.eval()
    with torch.no_grad():
        logits = net(batch.crops)
    net.train(was_training)
    predicted = torch.stack([slot.argmax(dim=1) for slot in logits], dim=1)
    return float((predicted == batch.labels).all(dim=1).float().mean())


def slot_loss(logits: list[Tensor], labels: Tensor, criterion: nn.Module) -> Tensor:
    """The mean over character slots of `criterion` (per-slot logits against the slots' class indices)."""
    return sum((criterion(slot, labels[:, i]) for i, slot in enumerate(logits)), torch.zeros(())) / len(logits)


def optimiser(net: nn.Module, budget: ReaderBudget) -> tuple[torch.optim.Optimizer, torch.optim.lr_scheduler.LambdaLR,
                                                              nn.Module]:
    """The recipe's optimiser, schedule and loss (module docstring): AdamW, a tenth of the steps warm-up,
    then cosine; cross-entropy with label smoothing 0.05."""
    optimizer = torch.optim.AdamW(net.parameters(), lr=budget.lr, weight_decay=1e-4)
    warmup, total = max(1, budget.max_steps // 10), max(budget.max_steps, 1)
    schedule = torch.optim.lr_scheduler.LambdaLR(
        optimizer, lambda s: min(1.0, (s + 1) / warmup) * 0.5 * (1.0 + math.cos(math.pi * min(s, total) / total)))
    return optimizer, schedule, nn.CrossEntropyLoss(label_smoothing=0.05)


def train_reader(net: PlateCNN, cameras: list[Camera | None], budget: ReaderBudget, spread_px: float,
                 psf_half_px: int, fmt: str, seed: int, held_out: dict[int, PlateBatch]) -> FitCurve:
    """Train ``net`` in place on plates through ``cameras`` (taken in turn, one per batch), stopping
    where the held-out accuracy flattens (module docstring). Deterministic for a seed and thread count:
    the batches come from ``seed``, and so does dropout (torch's global generator, forked and restored)."""
    with torch.random.fork_rng(devices=[]):
        torch.manual_seed(seed)
        return _train(net, cameras, budget, spread_px, psf_half_px, fmt, seed, held_out)


def _train(net: PlateCNN, cameras: list[Camera | None], budget: ReaderBudget, spread_px: float,
           psf_half_px: int, fmt: str, seed: int, held_out: dict[int, PlateBatch]) -> FitCurve:
    rng, generator = np.random.default_rng([seed, 0]), torch.Generator().manual_seed(seed)
    optimizer, schedule, criterion = optimiser(net, budget)
    curve = FitCurve([], [], [], "budget", False, 0.0)
    best: dict[str, Tensor] | None = None  # the weights of the best evaluation so far
    t0 = time.perf_counter()

    def evaluate(step: int) -> None:
        nonlocal best
        per_width = {w: plate_accuracy(net, b) for w, b in held_out.items()}
        curve.steps.append(step)
        curve.per_width.append(per_width)
        curve.accuracy.append(float(np.mean(list(per_width.values()))) if per_width else 0.0)
        if best is None or curve.accuracy[-1] > max(curve.accuracy[:-1]):
            best = {k: v.detach().clone() for k, v in net.state_dict().items()}
            curve.best_step = step
        log.info("plate reader step %d: held-out %.3f (%.0f s)", step, curve.accuracy[-1], time.perf_counter() - t0)

    if budget.eval_start:
        evaluate(0)
    net.train()
    bar = tqdm(range(budget.max_steps), desc="plate reader fit", unit="step", leave=False)
    for step in bar:
        crops, labels = training_batch(cameras[step % len(cameras)], budget, rng, generator, spread_px, fmt,
                                       psf_half_px)
        loss = slot_loss(net(crops), labels, criterion)
        optimizer.zero_grad(set_to_none=True)
        loss.backward()
        optimizer.step()
        schedule.step()
        if (step + 1) % budget.eval_every == 0 or step + 1 == budget.max_steps:
            evaluate(step + 1)
            bar.set_postfix(held_out=f"{curve.accuracy[-1]:.3f}")
            if step + 1 >= budget.min_steps and flattened(curve.accuracy, budget):
                curve.stopped = "flattened"
                break
    curve.still_rising = curve.stopped == "budget" and held_out_gain(curve.accuracy, budget.patience) >= budget.min_gain
    curve.seconds = round(time.perf_counter() - t0, 1)
    if best is not None and curve.best_step != curve.steps[-1]:
        net.load_state_dict(best)
    net.eval()
    return curve


def width_bands(budget: ReaderBudget) -> list[tuple[float, float]]:
    """The ``bands_per_batch`` log-spaced (low, high) bands of the budget's width range."""
    low, high = budget.widths_px
    edges = np.exp(np.linspace(math.log(low), math.log(high), budget.bands_per_batch + 1))
    return [(float(a), float(b)) for a, b in zip(edges[:-1], edges[1:])]


def training_batch(camera: Camera | None, budget: ReaderBudget, rng: np.random.Generator, generator: torch.Generator,
                   spread_px: float, fmt: str, psf_half_px: int) -> tuple[Tensor, Tensor]:
    """One training batch (crops, labels): ``batch_size`` plates split as evenly as it goes over the
    budget's ``width_bands``, one camera call per band, in band order."""
    bands = width_bands(budget)
    each, extra = divmod(budget.batch_size, len(bands))
    parts = [simulate_plates(camera, each + (k < extra), band, rng, generator, spread_px, fmt, psf_half_px)
             for k, band in enumerate(bands)]
    return torch.cat([p.crops for p in parts]), torch.cat([p.labels for p in parts])


def held_out_gain(accuracy: list[float], patience: int) -> float:
    """How much the last ``patience`` evaluations raised the best accuracy seen before them."""
    if len(accuracy) <= patience:
        return float("inf") if accuracy else 0.0
    return max(accuracy[-patience:]) - max(accuracy[:-patience])


def flattened(accuracy: list[float], budget: ReaderBudget) -> bool:
    return len(accuracy) > budget.patience and held_out_gain(accuracy, budget.patience) < budget.min_gain
