"""Pre-training of ``nafnet-known-psf`` across the lens family, once, until its held-out PSNR flattens.

What the network sees (``psf_inputs``): the sensor image Wiener-deconvolved with the lens's
measured PSF, gain and the noise measured on the image (``attacks.restorers.wiener_known_psf``),
beside the white-balanced sensor image itself; it outputs the Wiener estimate plus a residual. The
PSF thus enters as the physics says it acts, through the one linear inverse that knows it, and the
network learns what Wiener cannot: the noise it amplifies, the frequencies the lens erased, the
ringing at the OTF's zeros.

Training data. Scenes: sharp TRAIN images handed in by the caller (the shipped fit: synthetic TRAIN
scenes, ``benchmark.publish.ship_attacker``; a run without shipped weights: its own TRAIN scenes), never
the benchmark's val scenes. Lenses: drawn from ``LensFamily``. A pool of
``pool_lenses`` lenses, each with ``images_per_lens`` whole scenes sensed and deconvolved at full size
(so the network trains on exactly what it meets in a run, borders included), is refreshed one lens
every ``refresh_every`` steps; a step takes ``batch_size`` random crops of ``crop_px`` from the pool.
Every draw (lens, scenes, sensor noise, crops) is a function of (seed, refresh or step index), so a
run resumed from its checkpoint continues exactly.

Held out: ``heldout_lenses`` lenses drawn from the same family with another seed stream (lenses not
drawn in training), each on held-out scenes handed in by the caller (not among the training scenes); the score is the mean PSNR on the
central half of those images (sensed and deconvolved whole). Evaluated every ``eval_every`` steps;
the fit stops "flattened" when the best score of the last ``patience_evals`` evaluations is less than
``min_gain_db`` above the best before them, else at ``max_steps`` ("budget"; ``still_rising`` when the
last window still gained). The weights of the best evaluation are kept.

Recipe: NAFNet's (``attacks.training.restorer_training``): negative PSNR, AdamW (lr 1e-3, betas 0.9,
0.9, weight decay 1e-3), cosine schedule over ``max_steps`` (or, with ``cycle_steps``, cosine cycles with warm
restarts, SGDR: the learning rate back at 1e-3 at each cycle's start), gradients clipped to norm 1. The shipped
fit runs cycles of 2,500 steps, each continuing from the shipped weights of the cycles before it
(``PsfPretrainBudget.first_cycles``, ``benchmark.publish.ship_attacker.ship_known_psf``).
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

from attacks.backends.real_fft import OtfCache
from attacks.base import FitCurve
from attacks.networks.nafnet import NAFNet
from attacks.backends.wiener import bayer_noise_sigma, wiener_chunks, wiener_deconvolve
from attacks.training.lens_family import FamilyLens, LensFamily
from attacks.training.restorer_training import negative_psnr

log = logging.getLogger(__name__)

__all__ = ["FINE_TUNE_FIRST_EVAL", "FINE_TUNE_LR", "PSF_BUDGETS", "PretrainCurve", "PsfPretrainBudget", "build_network",
           "centre", "fine_tune", "pretrain", "psf_budget", "psf_inputs", "stream_generator"]

HELDOUT_SEED_OFFSET = 1_000_003  # the held-out lenses' stream (seed, this, i); training draws are (seed, index)
_LR, _LR_MIN, _BETAS, _WEIGHT_DECAY, _GRAD_CLIP = 1e-3, 1e-7, (0.9, 0.9), 1e-3, 1.0


@dataclasses.dataclass(frozen=True)
class PsfPretrainBudget:
    """Network size and training schedule of the pre-training (module docs name each field)."""

    width: int
    enc_blocks: tuple[int, ...]
    middle_blocks: int
    dec_blocks: tuple[int, ...]
    max_steps: int
    batch_size: int
    crop_px: int
    pool_lenses: int
    images_per_lens: int
    refresh_every: int
    eval_every: int
    heldout_lenses: int
    patience_evals: int
    min_gain_db: float
    cycle_steps: int = 0  # 0: one cosine over max_steps; else cosine cycles of this length (warm restarts)
    sharp_share: float = 0.0  # share of near-sharp lenses among the draws (``LensFamily``) ...
    sharp_from: int = 0  # ... of the refreshes from this step on
    heldout_sharp: int = 0  # near-sharp lenses held out beside the ``heldout_lenses`` others

    def __post_init__(self) -> None:
        for name in ("width", "max_steps", "batch_size", "crop_px", "pool_lenses", "images_per_lens",
                     "refresh_every", "eval_every", "heldout_lenses", "patience_evals"):
            if int(getattr(self, name)) < 1:
                raise ValueError(f"PsfPretrainBudget.{name} must be >= 1, got {getattr(self, name)!r}")
        if self.crop_px % 2:
            raise ValueError(f"PsfPretrainBudget.crop_px must be even (keeps the Bayer phase), got {self.crop_px}")
        if not 0.0 <= self.sharp_share <= 1.0 or self.sharp_from < 0 or self.heldout_sharp < 0:
            raise ValueError(f"PsfPretrainBudget: sharp_share must be in [0, 1] and sharp_from, heldout_sharp >= 0, "
                             f"got {self.sharp_share!r}, {self.sharp_from!r}, {self.heldout_sharp!r}")
        if self.cycle_steps and (self.cycle_steps < 0 or self.max_steps % self.cycle_steps
                                 or self.cycle_steps % self.eval_every):
            raise ValueError(f"PsfPretrainBudget.cycle_steps={self.cycle_steps} must divide max_steps "
                             f"({self.max_steps}) and be a multiple of eval_every ({self.eval_every})")

    @property
    def cycle(self) -> int:
        """The length of one cosine cycle (the whole budget without warm restarts)."""
        return self.cycle_steps or self.max_steps

    def first_cycles(self) -> PsfPretrainBudget | None:
        """The budget of every cycle but the last (what a warm start continues), None with one cycle."""
        if self.cycle >= self.max_steps:
            return None
        steps = self.max_steps - self.cycle
        earlier = dataclasses.replace(self, max_steps=steps, cycle_steps=0 if steps == self.cycle else self.cycle)
        if steps <= self.sharp_from:  # the near-sharp lenses came in later
            earlier = dataclasses.replace(earlier, sharp_share=0.0, sharp_from=0, heldout_sharp=0)
        return earlier

    def family(self) -> LensFamily:
        """The lens family this budget draws from."""
        return LensFamily(self.sharp_share)

    def to_dict(self) -> dict[str, Any]:
        """The fields (``cycle_steps`` and the near-sharp ones only when set: the keys of budgets made before
        them stay valid)."""
        d = dataclasses.asdict(self)
        for name in ("cycle_steps", "sharp_share", "sharp_from", "heldout_sharp"):
            if not d[name]:
                del d[name]
        return d


PSF_BUDGETS: dict[str, PsfPretrainBudget] = {
    # The shipped pre-training (quick and paper profiles share it: a convolutional network is
    # size-agnostic and the PSFs are in sensor pixels either way).
    # Cosine cycles of 2,500 steps, each shipped (``nafnet-known-psf-full-s0``, ``-full5000-s0``, ...,
    # ``-full25000-s0``) and continued from by the next; the fifth gained 0.09 dB held-out over the fourth
    # (28.18 -> 28.27 dB), the sixth 0.09 dB. From the seventh on a quarter of the draws are near-sharp
    # lenses, two of them held out (the sharp lenses had needed minutes of fine-tuning per lens): on the
    # eight held-out lenses the seventh went 29.38 -> 29.60 dB, the eighth 29.79, the ninth 29.89, the tenth
    # 30.02 (still rising).
    "full": PsfPretrainBudget(width=16, enc_blocks=(1, 1, 2), middle_blocks=2, dec_blocks=(1, 1, 1),
                              max_steps=25000, batch_size=8, crop_px=128, pool_lenses=8, images_per_lens=6,
                              refresh_every=20, eval_every=250, heldout_lenses=6, patience_evals=4,
                              min_gain_db=0.05, cycle_steps=2500, sharp_share=0.25, sharp_from=15000,
                              heldout_sharp=2),
    # Tiny and smoke runs: seconds, so that the tests exercise the whole path.
    "small": PsfPretrainBudget(width=8, enc_blocks=(1, 1), middle_blocks=1, dec_blocks=(1, 1),
                               max_steps=12, batch_size=2, crop_px=32, pool_lenses=2, images_per_lens=2,
                               refresh_every=4, eval_every=4, heldout_lenses=2, patience_evals=2,
                               min_gain_db=0.05),
}


def psf_budget(profile: str) -> PsfPretrainBudget:
    """The pre-training budget for a run profile: "small" for tiny and smoke, else "full"."""
    return PSF_BUDGETS["small" if profile in ("tiny", "smoke") else "full"]


def build_network(budget: PsfPretrainBudget, seed: int) -> NAFNet:
    """The NAFNet of ``budget`` (Wiener estimate + 3 guide channels), initialised from ``seed``; its last
    convolution starts at zero, so the untrained network returns the Wiener estimate exactly."""
    with torch.random.fork_rng(devices=[]):
        torch.manual_seed(seed)
        net = NAFNet(width=budget.width, enc_blk_nums=budget.enc_blocks, middle_blk_num=budget.middle_blocks,
                     dec_blk_nums=budget.dec_blocks, guide_channels=3)
    with torch.no_grad():
        net.ending.weight.zero_()
        assert net.ending.bias is not None
        net.ending.bias.zero_()
    return net


def psf_inputs(sensor: Tensor, otf: OtfCache, gain: Tensor) -> Tensor:
    """The network's input (B, 6, H, W): the Wiener estimate and the white-balanced sensor image.

    Args:
        sensor: Sensor images (B, 3, H, W) in [0, 1] (demosaicked RGGB).
        otf: The lens's PSF (3, K, K) as an ``OtfCache``.
        gain: The lens's per-channel gain (3,).
    """
    g = gain.to(sensor).view(1, -1, 1, 1)
    deblurred = torch.cat([wiener_deconvolve(sensor[c], otf, sigma=bayer_noise_sigma(sensor[c]))
                           for c in wiener_chunks(sensor, otf.psf)])
    return torch.cat([(deblurred / g).clamp(0.0, 1.0), (sensor / g).clamp(0.0, 1.0)], dim=1)


def stream_generator(*parts: int) -> torch.Generator:
    """A generator seeded by a hash of ``parts`` (non-negative integers): one stream per (seed, index)."""
    state = np.random.SeedSequence([int(p) for p in parts]).generate_state(1, np.uint64)[0]
    return torch.Generator().manual_seed(int(state) >> 1)


def _crops(pool: list[tuple[Tensor, Tensor]], n: int, crop_px: int, g: torch.Generator) -> tuple[Tensor, Tensor]:
    """``n`` random (input, target) crops of ``crop_px`` (even offsets) from random images of the pool."""
    inputs, targets = [], []
    for _ in range(n):
        x, y = pool[int(torch.randint(len(pool), (1,), generator=g))]
        i = int(torch.randint(x.shape[0], (1,), generator=g))
        h, w = min(crop_px, x.shape[-2]) // 2 * 2, min(crop_px, x.shape[-1]) // 2 * 2
        top = int(torch.randint((x.shape[-2] - h) // 2 + 1, (1,), generator=g)) * 2
        left = int(torch.randint((x.shape[-1] - w) // 2 + 1, (1,), generator=g)) * 2
        inputs.append(x[i, :, top:top + h, left:left + w])
        targets.append(y[i, :, top:top + h, left:left + w])
    return torch.stack(inputs), torch.stack(targets)


def _render(family: LensFamily, drawn: FamilyLens, sharp: Tensor, noise_seed: int) -> Tensor:
    """Network inputs (N, 6, H, W) of the sharp scenes through the drawn lens."""
    lens = family.build(drawn)
    with torch.no_grad():
        sensor = torch.cat([lens(sharp[i:i + 1], generator=torch.Generator().manual_seed(noise_seed + i))
                            for i in range(sharp.shape[0])])
        return psf_inputs(sensor, OtfCache(lens.psf().detach()), lens.gain().detach())


@dataclasses.dataclass
class PretrainCurve:
    """The held-out curve of a pre-training; ``to_fit_curve`` gives the runner's ``FitCurve``."""

    steps: list[int] = dataclasses.field(default_factory=list)
    heldout_psnr_db: list[float] = dataclasses.field(default_factory=list)
    wiener_psnr_db: float | None = None  # the same held-out images restored by Wiener alone
    stopped: str = "budget"
    still_rising: bool = False
    seconds: float = 0.0
    heldout: list[dict[str, Any]] = dataclasses.field(default_factory=list)  # the held-out lenses
    kept: int | None = None  # the step whose weights were kept, where that is not simply the best one
    # With near-sharp held-out lenses: the mean over them and over the others, per evaluation.
    sharp_psnr_db: list[float] = dataclasses.field(default_factory=list)
    others_psnr_db: list[float] = dataclasses.field(default_factory=list)
    # The curve before a warm start that changed the held-out set (its own steps, scores and lenses).
    before: dict[str, Any] | None = None

    @property
    def kept_step(self) -> int:
        if self.kept is not None:
            return self.kept
        return self.steps[max(range(len(self.steps)), key=self.heldout_psnr_db.__getitem__)] if self.steps else 0

    def to_fit_curve(self) -> FitCurve:
        return FitCurve(tuple(self.steps), tuple(self.heldout_psnr_db), "held-out PSNR (dB), lenses not drawn in training",
                        self.stopped, self.kept_step)

    def to_dict(self) -> dict[str, Any]:
        return {**dataclasses.asdict(self), "kept_step": self.kept_step}

    @classmethod
    def from_dict(cls, d: dict[str, Any]) -> PretrainCurve:
        fields = {f.name for f in dataclasses.fields(cls)}
        return cls(**{k: v for k, v in d.items() if k in fields})


def _psnr(x: Tensor, y: Tensor) -> Tensor:
    return -10.0 * torch.log10((x.clamp(0, 1) - y).pow(2).flatten(1).mean(1).clamp_min(1e-10))


def centre(x: Tensor) -> Tensor:
    """The central half of images (..., H, W) in both axes: the held-out region, away from the borders."""
    h, w = x.shape[-2:]
    return x[..., h // 4: h // 4 + h // 2, w // 4: w // 4 + w // 2]


def _train_step(model: NAFNet, optimizer: torch.optim.Optimizer, schedule: torch.optim.lr_scheduler.LRScheduler,
                pool: list[tuple[Tensor, Tensor]], batch_size: int, crop_px: int, g: torch.Generator,
                device: str) -> float:
    """One optimiser step on crops of the pool (channels-last input, the recipe's clip); returns the loss."""
    inp, target = _crops(pool, batch_size, crop_px, g)
    loss = negative_psnr(model(inp.to(device, memory_format=torch.channels_last)), target.to(device))
    optimizer.zero_grad(set_to_none=True)
    loss.backward()
    nn.utils.clip_grad_norm_(model.parameters(), _GRAD_CLIP)
    optimizer.step()
    schedule.step()
    return loss.item()


def _heldout_psnr(model: NAFNet, pairs: list[tuple[Tensor, Tensor]], device: str) -> float:
    """Mean PSNR (dB) over every image of the (input, target) batches; the model is back in train mode after."""
    return float(torch.cat(_heldout_scores(model, pairs, device)).mean())


def _heldout_scores(model: NAFNet, pairs: list[tuple[Tensor, Tensor]], device: str) -> list[Tensor]:
    """PSNR (dB) of every image, one tensor per (input, target) batch; the model is back in train mode after."""
    model.eval()
    with torch.no_grad():
        scores = [_psnr(model(x.to(device)).cpu(), y) for x, y in pairs]
    model.train()
    return scores


def _record(curve: PretrainCurve, step: int, scores: list[Tensor], n_others: int) -> float:
    """Appends an evaluation (per-lens image scores, the near-sharp lenses after the first ``n_others``) to
    ``curve``; returns its score, the mean over every image."""
    score = float(torch.cat(scores).mean())
    curve.steps.append(step)
    curve.heldout_psnr_db.append(score)
    if len(scores) > n_others:
        curve.others_psnr_db.append(float(torch.cat(scores[:n_others]).mean()))
        curve.sharp_psnr_db.append(float(torch.cat(scores[n_others:]).mean()))
    return score


def _flattened(scores: list[float], patience: int, min_gain: float) -> tuple[bool, bool]:
    """(flattened, still rising) of a held-out curve under the patience rule (module docs)."""
    if len(scores) <= patience:
        return False, True
    gain = max(scores[-patience:]) - max(scores[:-patience])
    return gain < min_gain, gain >= min_gain


def pretrain(budget: PsfPretrainBudget, scenes: Tensor, heldout_scenes: Tensor, seed: int, device: str = "cpu",
             checkpoint: Path | None = None, family: LensFamily | None = None,
             progress: Callable[[str], None] | None = None,
             warm_start: tuple[dict[str, Tensor], PretrainCurve] | None = None) -> tuple[NAFNet, PretrainCurve]:
    """Pre-train the known-PSF restorer across the lens family (module docs).

    Args:
        budget: Size and schedule.
        scenes: Sharp TRAIN images (N, 3, H, W) in [0, 1], N >= 1.
        heldout_scenes: Sharp held-out images (M, 3, H, W), none of them in ``scenes``.
        seed: Seeds the weights and every draw.
        device: Where the network trains (rendering stays on the CPU).
        checkpoint: A file to resume from and to write every evaluation to (``torch.save`` of tensors
            and plain values, read back with ``weights_only=True``); None keeps nothing.
        family: The lens family (default ``budget.family()``).
        progress: Called with one line per evaluation (besides the log).
        warm_start: The weights and curve of this budget's first cycles (``first_cycles``: the same seed,
            scenes and draws) to continue from at the restart, where no checkpoint exists. The optimiser's
            moments start afresh there (a fit run through its restart would carry them over).

    Returns:
        The network with the kept (best held-out) weights, on the CPU, in eval mode, and its curve.

    With cosine cycles (``cycle_steps``) the stop rule is read at each cycle's end only: the fit stops
    "flattened" when that cycle's best held-out score is less than ``min_gain_db`` above the best before it
    (the restart's high learning rate makes the first evaluations of a cycle fall).

    Near-sharp lenses (``budget.sharp_share``, ``sharp_from``, ``heldout_sharp``): the refreshes from step
    ``sharp_from`` on may draw them, and ``heldout_sharp`` of them join the held-out set (its score is the
    mean over all its lenses; the curve keeps the mean over each kind too). A warm start whose curve was
    scored on another held-out set scores its start on this one: the curve goes on from there, and the
    earlier one is kept whole in ``curve.before``.
    """
    if scenes.ndim != 4 or scenes.shape[0] < 1 or heldout_scenes.ndim != 4 or heldout_scenes.shape[0] < 1:
        raise ValueError(f"pretrain needs (N, 3, H, W) train and held-out scenes, got {tuple(scenes.shape)} "
                         f"and {tuple(heldout_scenes.shape)}")
    family = family or budget.family()
    model = build_network(budget, seed).to(device)
    optimizer = torch.optim.AdamW(model.parameters(), lr=_LR, betas=_BETAS, weight_decay=_WEIGHT_DECAY)
    schedule: torch.optim.lr_scheduler.LRScheduler = (
        torch.optim.lr_scheduler.CosineAnnealingWarmRestarts(optimizer, T_0=budget.cycle_steps, eta_min=_LR_MIN)
        if budget.cycle_steps else
        torch.optim.lr_scheduler.CosineAnnealingLR(optimizer, T_max=budget.max_steps, eta_min=_LR_MIN))
    curve, best_state, start = PretrainCurve(), None, 0
    if warm_start is not None and not (checkpoint is not None and checkpoint.exists()):
        state, before = warm_start
        start = before.steps[-1] if before.steps else 0
        if start % budget.cycle or start >= budget.max_steps:
            raise ValueError(f"a warm start continues at a cycle's end before max_steps ({budget.cycle}-step cycles "
                             f"of {budget.max_steps}); its curve ends at step {start}")
        model.load_state_dict(state)
        best_state = {k: v.detach().cpu().clone() for k, v in model.state_dict().items()}
        curve = PretrainCurve.from_dict(before.to_dict())
        curve.stopped, curve.still_rising = "budget", False
        for _ in range(start):
            schedule.step()
        log.info("nafnet-known-psf pre-training continues from step %d (warm restart)", start)
    elif checkpoint is not None and checkpoint.exists():
        saved = torch.load(checkpoint, weights_only=True)
        model.load_state_dict(saved["model"])
        optimizer.load_state_dict(saved["optimizer"])
        schedule.load_state_dict(saved["schedule"])
        curve, best_state, start = PretrainCurve.from_dict(saved["curve"]), saved["best"], int(saved["step"])
        log.info("nafnet-known-psf pre-training resumed at step %d from %s", start, checkpoint)

    # Held-out set: fixed lenses of another seed stream, each on every held-out scene (near-sharp ones last).
    n_lenses = budget.heldout_lenses + budget.heldout_sharp
    heldout_draws = [family.draw(stream_generator(seed, HELDOUT_SEED_OFFSET, i), sharp=i >= budget.heldout_lenses)
                     for i in range(n_lenses)]
    heldout = [(centre(_render(family, d, heldout_scenes, 10_000 * (i + 1))), centre(heldout_scenes))
               for i, d in enumerate(heldout_draws)]
    described = [d.describe() for d in heldout_draws]
    if curve.steps and curve.heldout and curve.heldout != described:  # a warm start onto another held-out set
        curve = PretrainCurve(seconds=curve.seconds, before=curve.to_dict())
        _record(curve, start, _heldout_scores(model, heldout, device), budget.heldout_lenses)
        log.info("nafnet-known-psf pre-training: the held-out set changed at step %d; the start scores %.2f dB on "
                 "the new one", start, curve.heldout_psnr_db[0])
    curve.heldout = described
    curve.wiener_psnr_db = float(torch.cat([_psnr(x[:, :3], y) for x, y in heldout]).mean())


    def refresh(index: int) -> tuple[Tensor, Tensor]:
        g = stream_generator(seed, index, 0)
        drawn = family.draw(g, sharp=False if index * budget.refresh_every < budget.sharp_from else None)
        chosen = torch.randperm(scenes.shape[0], generator=g)[:budget.images_per_lens]
        return _render(family, drawn, scenes[chosen], 1_000_000 + index * 1000), scenes[chosen]

    # During step s the pool holds the lenses of refreshes [s // refresh_every, + pool_lenses).
    first = start // budget.refresh_every
    pool = [refresh(r) for r in range(first, first + budget.pool_lenses)]
    t0 = time.perf_counter() - curve.seconds
    # Channels-last weights: the convolutions' backward copies no activations between layouts (measured
    # 2.0 against 3.0 s a step on one core); evaluation and the returned network use the default layout.
    model.to(memory_format=torch.channels_last).train()
    bar = tqdm(range(start, budget.max_steps), desc="nafnet-known-psf pre-training", unit="step",
               initial=start, total=budget.max_steps, leave=False)
    for step in bar:
        if step != start and step % budget.refresh_every == 0:
            pool = pool[1:] + [refresh(step // budget.refresh_every + budget.pool_lenses - 1)]
        loss = _train_step(model, optimizer, schedule, pool, budget.batch_size, budget.crop_px,
                           stream_generator(seed, step, 1), device)
        bar.set_postfix(psnr_db=f"{-loss:.2f}")
        if (step + 1) % budget.eval_every == 0 or step + 1 == budget.max_steps:
            score = _record(curve, step + 1, _heldout_scores(model, heldout, device), budget.heldout_lenses)
            if score >= max(curve.heldout_psnr_db):
                best_state = {k: v.detach().cpu().clone() for k, v in model.state_dict().items()}
            curve.seconds = time.perf_counter() - t0
            if budget.cycle_steps:  # read at a cycle's end only, over that cycle's evaluations
                per_cycle = budget.cycle_steps // budget.eval_every
                flat, rising = ((False, curve.still_rising) if (step + 1) % budget.cycle_steps else
                                _flattened(curve.heldout_psnr_db, per_cycle, budget.min_gain_db))
            else:
                flat, rising = _flattened(curve.heldout_psnr_db, budget.patience_evals, budget.min_gain_db)
            curve.still_rising = rising
            kinds = (f"; near-sharp {curve.sharp_psnr_db[-1]:.2f}, others {curve.others_psnr_db[-1]:.2f} dB"
                     if budget.heldout_sharp else "")
            line = (f"step {step + 1}/{budget.max_steps}: held-out {score:.2f} dB (Wiener {curve.wiener_psnr_db:.2f} dB"
                    f"{kinds}), {curve.seconds:.0f} s")
            if checkpoint is not None:
                checkpoint.parent.mkdir(parents=True, exist_ok=True)
                tmp = checkpoint.with_suffix(".tmp")
                torch.save({"model": model.state_dict(), "optimizer": optimizer.state_dict(),
                            "schedule": schedule.state_dict(), "curve": curve.to_dict(), "best": best_state,
                            "step": step + 1}, tmp)
                tmp.replace(checkpoint)
            log.info("nafnet-known-psf pre-training %s", line)
            if progress is not None:
                progress(line)
            if flat:
                curve.stopped, curve.still_rising = "flattened", False
                break
    bar.close()
    model.to(memory_format=torch.contiguous_format)
    if best_state is not None:
        model.load_state_dict(best_state)
    return model.cpu().eval(), curve


FINE_TUNE_LR = 2e-4
"""Peak learning rate of a fine-tune (a fifth of the pre-training's: the start is already good)."""
FINE_TUNE_FIRST_EVAL = 25
"""Steps of a fine-tune's first held-out evaluation after the start; each later one doubles them."""


def fine_tune(model: NAFNet, inputs: Tensor, targets: Tensor, heldout_inputs: Tensor, heldout_targets: Tensor,
              max_steps: int, crop_px: int, batch_size: int, seed: int, min_gain_db: float = 0.05,
              device: str = "cpu") -> PretrainCurve:
    """Fine-tune ``model`` in place on one lens's pairs until its held-out PSNR flattens on a log-step axis.

    Evaluated at the start (step 0: the pre-trained network as it is) and after 25, 50, 100, ... steps
    (at most ``max_steps``, the cosine schedule's length); it stops "flattened" at the first doubling of
    the steps that gains less than ``min_gain_db``, else "budget" (``still_rising`` when the last
    doubling still gained). The start is kept unless a step beats it by ``min_gain_db`` (a held-out gain
    below the stop rule's own threshold is noise that need not carry to other scenes); of the steps that do,
    the best one is kept. So a fine-tune never hands back a network worse on the held-out pairs than the
    one it started from, and ``curve.kept`` names the step it hands back.

    Args:
        model: The pre-trained network (input ``psf_inputs``, 6 channels).
        inputs, targets: Training pairs (N, 6, H, W) and (N, 3, H, W).
        heldout_inputs, heldout_targets: Held-out pairs of the same lens, not among the training ones.
    """
    model.to(device)
    optimizer = torch.optim.AdamW(model.parameters(), lr=FINE_TUNE_LR, betas=_BETAS, weight_decay=_WEIGHT_DECAY)
    schedule = torch.optim.lr_scheduler.CosineAnnealingLR(optimizer, T_max=max(max_steps, 1), eta_min=_LR_MIN)
    curve = PretrainCurve()
    t0 = time.perf_counter()
    best: dict[str, Tensor] = {}
    best_score = -float("inf")

    def evaluate(step: int) -> None:
        nonlocal best, best_score
        score = _heldout_psnr(model, [(heldout_inputs[i:i + 1], heldout_targets[i:i + 1])
                                      for i in range(heldout_inputs.shape[0])], device)
        curve.steps.append(step)
        curve.heldout_psnr_db.append(score)
        if step == 0 or (score >= curve.heldout_psnr_db[0] + min_gain_db and score > best_score):
            best, best_score, curve.kept = {k: v.detach().cpu().clone() for k, v in model.state_dict().items()}, score, step

    evaluate(0)
    next_eval = min(FINE_TUNE_FIRST_EVAL, max_steps)
    pool = [(inputs, targets)]
    model.to(memory_format=torch.channels_last).train()
    for step in range(max_steps):
        _train_step(model, optimizer, schedule, pool, batch_size, crop_px, stream_generator(seed, step, 2), device)
        if step + 1 == next_eval:
            evaluate(step + 1)
            gain = curve.heldout_psnr_db[-1] - curve.heldout_psnr_db[-2]
            curve.still_rising = gain >= min_gain_db
            log.info("fine-tune step %d/%d: held-out %.2f dB (%+.2f dB)", step + 1, max_steps, curve.heldout_psnr_db[-1], gain)
            if not curve.still_rising:
                curve.stopped = "flattened"
                break
            next_eval = min(2 * next_eval, max_steps)
    curve.seconds = time.perf_counter() - t0
    model.to(memory_format=torch.contiguous_format)
    model.load_state_dict(best)
    model.cpu().eval()
    return curve
