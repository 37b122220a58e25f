"""Pre-training of ``learned-reader`` across the lens family, once, so it reads a lens it never saw.

The start of every lens's fit. It continues from the sharp-plate start (``learned-reader-sharp-s0``:
glyphs, no lens) and trains on plates simulated through lenses drawn from ``LensFamily`` (the co-design
box and the out-of-focus lenses), one lens a step: the step's lens, its crops cut with that lens's PSF
spread (``psf_radius_px``: the margin the crop holds grows with the blur, which is how the PSF reaches
the network), and the batch split over width bands as the per-lens fits do (``training_batch``).
Every draw (lens, plates, noise, dropout) is a function of (seed, step), so a run resumed from its checkpoint
continues exactly.

What the reader reads (``reads``): "sensor", the sensor image, its crop holding the blur's spread (the
start of ``learned-reader``'s per-lens fits); or "wiener", the per-colour Wiener estimate of the sensor
patch made with the drawn lens's PSF and gain at the noise measured on the patch (``psf_inputs``, as
``learned-reader-psf`` reads a run's images), cut around the box with no blur margin. With "wiener" the
PSF reaches the network through the one linear inverse that knows it, and the network learns to read
what Wiener leaves: amplified noise, ringing, the frequencies the lens erased.

Held out: ``heldout_lenses`` lenses drawn from the same family with another seed stream (not drawn in
training), ``eval_plates`` plates each per width bin of ``EVAL_WIDTHS_PX`` (true boxes); the score is
the mean exact-plate accuracy over lenses and bins. Evaluated at the start and every ``eval_every``
steps; the fit stops "flattened" when the last ``patience`` evaluations gained less than ``min_gain``
over the best before them (never before ``min_steps``), else at ``max_steps`` ("budget", with
``still_rising`` when the last window still gained). The weights of the best evaluation are kept.

Recipe: the per-lens fits' (``attacks.training.plate_reader_training``): per-slot cross-entropy with
label smoothing 0.05, AdamW (weight decay 1e-4), a tenth of the steps warm-up, then cosine.
"""

from __future__ import annotations

import dataclasses
import logging
import time
from collections.abc import Callable
from pathlib import Path
from typing import Any

import numpy as np
import torch
from torch import Tensor, nn
from tqdm.auto import tqdm

from attacks.networks.plate_cnn import PlateCNN
from attacks.readers.plates.plate_sim import PlateBatch, psf_radius_px, psf_support_px
from attacks.training.lens_family import FamilyLens, LensFamily
from attacks.training.plate_reader_training import (
    FitCurve, ReaderBudget, flattened, held_out_gain, held_out_set, optimiser, plate_accuracy, slot_loss, training_batch)
from attacks.backends.real_fft import OtfCache
from attacks.training.psf_restorer_training import psf_inputs, stream_generator

__all__ = ["FAMILY_BUDGET", "READS", "FamilyCamera", "family_camera", "family_held_out", "lens_camera", "pretrain_family"]

READS = ("sensor", "wiener")
"""What the reader reads (module docs)."""

log = logging.getLogger(__name__)

HELDOUT_SEED_OFFSET = 2_000_003  # the held-out lenses' stream (seed, this, i); training draws are (seed, step)


@dataclasses.dataclass(frozen=True)
class FamilyBudget:
    """The family pre-training's size: a ``ReaderBudget`` for the steps, plus the held-out lenses."""

    steps: ReaderBudget
    heldout_lenses: int

    def to_dict(self) -> dict[str, Any]:
        return {**self.steps.to_dict(), "heldout_lenses": self.heldout_lenses}


FAMILY_BUDGET = FamilyBudget(
    ReaderBudget(max_steps=6000, batch_size=48, lr=1e-3, widths_px=(8.0, 200.0), eval_every=500, eval_plates=32,
                 patience=3, min_gain=0.005, min_steps=2000, bands_per_batch=4),
    heldout_lenses=6)
"""The shipped pre-training (``python -m benchmark pretrain-attacker learned-reader --family``)."""


@dataclasses.dataclass(frozen=True)
class FamilyCamera:
    """One drawn lens as the reader's training sees it: its camera and the PSF facts a crop needs."""

    drawn: FamilyLens
    camera: Callable[[Tensor, torch.Generator], Tensor]
    spread_px: float
    psf_half_px: int


def family_camera(family: LensFamily, drawn: FamilyLens, reads: str = "sensor") -> FamilyCamera:
    """The camera of a drawn lens (CPU; the mask lens is shared, so use it before the next draw): the
    sensor image, or with ``reads="wiener"`` its Wiener estimate (module docs; crops then hold no margin)."""
    camera, spread_px, half = lens_camera(family.build(drawn), reads)
    return FamilyCamera(drawn, camera, spread_px, half)


def lens_camera(lens: Any, reads: str = "sensor", device: str = "cpu", support_energy: float | None = None
                ) -> tuple[Callable[[Tensor, torch.Generator], Tensor], float, int]:
    """``(camera, spread_px, psf_half_px)`` of one lens (``lenses.Lens``, or anything with ``psf()``,
    ``gain()`` and ``lens(x, generator=g)``): its camera gives the sensor image of plates, or with
    ``reads="wiener"`` their Wiener estimate (module docs); ``spread_px`` is the margin a crop holds for
    the blur (none for a Wiener estimate); ``psf_half_px`` how far beyond a crop its patch reaches: half the PSF's
    support, or with ``support_energy`` the radius holding that much of its light (``psf_support_px``). The
    noise comes from a CPU generator whatever ``device``, and the camera returns CPU tensors, so a fit is
    the same on every device."""
    if reads not in READS:
        raise ValueError(f"reads={reads!r}: must be one of {', '.join(READS)}")
    with torch.no_grad():
        psf = lens.psf().detach().cpu()
        wiener = (OtfCache(psf), lens.gain().detach().cpu()) if reads == "wiener" else None

    def camera(x: Tensor, generator: torch.Generator) -> Tensor:
        with torch.no_grad():
            sensor = lens(x.to(device), generator=generator if device == "cpu" else None).cpu()
            return sensor if wiener is None else psf_inputs(sensor, *wiener)[:, :3]
    half = psf.shape[-1] // 2 if support_energy is None else psf_support_px(psf, support_energy)
    return camera, psf_radius_px(psf) if wiener is None else 0.0, half


def family_held_out(family: LensFamily, budget: FamilyBudget, fmt: str, seed: int, reads: str = "sensor"
                    ) -> list[tuple[FamilyLens, dict[int, PlateBatch]]]:
    """The fixed held-out sets: per held-out lens (another seed stream), its plates per width bin."""
    out = []
    for i in range(budget.heldout_lenses):
        through = family_camera(family, family.draw(stream_generator(seed, HELDOUT_SEED_OFFSET, i)), reads)
        out.append((through.drawn, held_out_set(through.camera, budget.steps, through.spread_px, through.psf_half_px,
                                                fmt, seed + 101 * (i + 1))))
    return out


def _evaluate(net: nn.Module, held_out: list[tuple[FamilyLens, dict[int, PlateBatch]]]) -> dict[int, float]:
    """Per width bin, the mean over the held-out lenses of the exact-plate accuracy."""
    widths = sorted(held_out[0][1]) if held_out else []
    return {w: float(np.mean([plate_accuracy(net, sets[w]) for _, sets in held_out])) for w in widths}


def pretrain_family(net: PlateCNN, fmt: str, seed: int, budget: FamilyBudget = FAMILY_BUDGET,
                    checkpoint: Path | None = None, family: LensFamily | None = None,
                    progress: Callable[[str], None] | None = None, reads: str = "sensor"
                    ) -> tuple[FitCurve, list[dict[str, Any]]]:
    """Train ``net`` (the sharp start, in place) across the lens family (module docs).

    Args:
        net: The reader to train; it ends on the weights of its best held-out evaluation, in eval mode.
        fmt: Plate format.
        seed: Seeds every draw (the network's own initialisation is the caller's).
        budget: Steps, batch and held-out size.
        checkpoint: A file to resume from and to write after every evaluation (``torch.save`` of tensors
            and plain values, read back with ``weights_only=True``); None keeps nothing.
        family: The lens family (default ``LensFamily()``).
        progress: Called with one line per evaluation (besides the log).
        reads: "sensor" or "wiener": what the reader reads (module docs).

    Returns:
        The held-out curve (mean over the held-out lenses per bin) and the held-out lenses' descriptions.
    """
    with torch.random.fork_rng(devices=[]):  # the global generator (dropout) is seeded per step, then restored
        return _pretrain(net, fmt, seed, budget, checkpoint, family or LensFamily(), progress, reads)


def _pretrain(net: PlateCNN, fmt: str, seed: int, budget: FamilyBudget, checkpoint: Path | None, family: LensFamily,
              progress: Callable[[str], None] | None, reads: str) -> tuple[FitCurve, list[dict[str, Any]]]:
    steps = budget.steps
    optimizer, schedule, criterion = optimiser(net, steps)
    held_out = family_held_out(family, budget, fmt, seed, reads)
    described = [d.describe() for d, _ in held_out]
    curve, best, start = FitCurve([], [], [], "budget", False, 0.0), None, 0
    if checkpoint is not None and checkpoint.exists():
        saved = torch.load(checkpoint, weights_only=True)
        net.load_state_dict(saved["net"])
        optimizer.load_state_dict(saved["optimizer"])
        schedule.load_state_dict(saved["schedule"])
        curve, best, start = FitCurve.from_dict(saved["curve"]), saved["best"], int(saved["step"])
        log.info("learned-reader family pre-training resumed at step %d from %s", start, checkpoint)

    def evaluate(step: int) -> bool:
        nonlocal best
        per_width = _evaluate(net, held_out)
        curve.steps.append(step)
        curve.per_width.append(per_width)
        curve.accuracy.append(float(np.mean(list(per_width.values()))))
        if best is None or curve.accuracy[-1] > max(curve.accuracy[:-1]):
            best, curve.best_step = {k: v.detach().clone() for k, v in net.state_dict().items()}, step
        curve.seconds = round(time.perf_counter() - t0, 1)
        flat = step >= steps.min_steps and flattened(curve.accuracy, steps)
        line = (f"step {step}/{steps.max_steps}: held-out {curve.accuracy[-1]:.3f} ("
                + ", ".join(f"{w} px {a:.2f}" for w, a in per_width.items()) + f"), {curve.seconds:.0f} s")
        if checkpoint is not None:
            checkpoint.parent.mkdir(parents=True, exist_ok=True)
            tmp = checkpoint.with_suffix(".tmp")
            torch.save({"net": net.state_dict(), "optimizer": optimizer.state_dict(), "schedule": schedule.state_dict(),
                        "curve": curve.to_dict(), "best": best, "step": step}, tmp)
            tmp.replace(checkpoint)
        log.info("learned-reader family pre-training %s", line)
        if progress is not None:
            progress(line)
        return flat

    t0 = time.perf_counter() - curve.seconds
    flat = False
    if start == 0:
        flat = evaluate(0)  # the sharp start, zero-shot on the held-out lenses
    net.train()
    bar = tqdm(range(start, steps.max_steps), desc="learned-reader family pre-training", unit="step", initial=start,
               total=steps.max_steps, leave=False)
    for step in bar:
        if flat:
            curve.stopped = "flattened"
            break
        g = stream_generator(seed, step)
        torch.manual_seed(int(torch.randint(0, 2**62, (1,), generator=stream_generator(seed, step, 2))))  # dropout's draws
        through = family_camera(family, family.draw(g), reads)
        rng = np.random.default_rng([seed, step, 1])
        crops, labels = training_batch(through.camera, steps, rng, g, through.spread_px, fmt, through.psf_half_px)
        loss = slot_loss(net(crops), labels, criterion)
        optimizer.zero_grad(set_to_none=True)
        loss.backward()
        optimizer.step()
        schedule.step()
        bar.set_postfix(loss=f"{loss.item():.3f}")
        if (step + 1) % steps.eval_every == 0 or step + 1 == steps.max_steps:
            flat = evaluate(step + 1)
            net.train()
            if flat:
                curve.stopped = "flattened"
                break
    bar.close()
    curve.still_rising = curve.stopped == "budget" and len(curve.accuracy) > steps.patience and (
        held_out_gain(curve.accuracy, steps.patience) >= steps.min_gain)
    if best is not None:
        net.load_state_dict(best)
    net.eval()
    return curve, described
