"""``learned-reader``: a CNN plate reader trained on plates simulated through the lens under test.

Threat model: lens access. The attacker can measure the camera (its PSF with a point source, its
gain with a flat field) and knows the country's plate format and font (public), so it renders as
many training plates as it needs and pushes them through the camera exactly as a run forms a
sensor image (``attacks.readers.plates.plate_sim``). It reads from the sensor image itself, where nothing
has been thrown away, given the plate box (``ReadHints.plate_boxes``, the hint ``lpdr-oracle`` and
``ideal-observer`` get): the box, grown by the PSF's spread, is resampled to a fixed crop and one
classifier per character slot reads it (``attacks.networks.plate_cnn``), its probabilities averaged
over nine views of the box (``VIEWS``: a detector's box is never exact, and neither is the grid). Chained after a restorer
it reads the restorer's output the same way (it was trained on sensor images, so this is the weaker
use of it).

Fitting: the network starts from the pre-training on sharp plates (clean renders with white noise,
``attacks/weights/learned-reader-sharp-s0.*``, ``python -m benchmark pretrain-attacker learned-reader``)
and is fine-tuned on the lens (``BUDGETS``) until its held-out accuracy flattens
(``attacks.training.plate_reader_training``). The curve is kept with the weights and comes back in the
``FitReport`` of ``fit``, which says whether it stopped while still rising. Weights are cached per (lens,
plate format, budget, start weights, fit seed: 0 by default, so a fixed lens is fitted once for every run
seed). Without shipped weights for the plate format (another ``--plate-format``), it pre-trains on sharp
plates here first: the full pre-training for the quick and paper budgets, the budget's own small one for smoke and tiny.
"""

from __future__ import annotations

import json
import logging
import time
from typing import Any, ClassVar

import torch
from safetensors import SafetensorError
from safetensors.torch import load as load_safetensors
from safetensors.torch import save as save_safetensors
from torch import Tensor

from attacks.base import FitContext, FitCurve as ReportedCurve, FitReport, PlateRead, ReadHints, Reader, ThreatModel
from attacks.networks.plate_cnn import PlateCNN
from attacks.training.plate_reader_training import FitCurve, ReaderBudget, held_out_set, train_reader
from attacks.training.reader_family_training import lens_camera
from common.plate_render import PLATE_FORMAT, format_alphabets
from attacks.readers.plates.plate_sim import plate_crops
from attacks.training.restorer_training import lens_key
from attacks.training.fit_code import versioned_key
from attacks.training.shipped_weights import Shipped, find_shipped, key_text

__all__ = ["BUDGETS", "PRETRAIN_BUDGET", "LearnedReader", "pack_weights", "pretrain", "pretrained_key", "start_budget",
           "unpack_weights"]

log = logging.getLogger(__name__)

WIDTH = 16  # PlateCNN's first-stage channels

PRETRAIN_BUDGET = ReaderBudget(max_steps=6000, batch_size=64, lr=3e-3, widths_px=(8.0, 200.0), eval_every=250,
                               eval_plates=64, patience=4)
"""Pre-training on sharp plates (``python -m benchmark pretrain-attacker learned-reader``)."""

BUDGETS: dict[str, ReaderBudget] = {
    "tiny": ReaderBudget(max_steps=2, batch_size=4, lr=1e-3, widths_px=(24.0, 64.0), eval_every=1, eval_plates=2,
                       patience=1),
    "smoke": ReaderBudget(max_steps=20, batch_size=16, lr=1e-3, widths_px=(8.0, 200.0), eval_every=10,
                          eval_plates=8, patience=2, bands_per_batch=4),
    # One 600-step cosine cycle at 3e-3, stopped after three evaluations without a point of gain: where the
    # 2400-step schedule with a 1200-step floor took 260-310 s a lens on 2 cores, this cycle took 86-141 s run
    # to its end (before SUPPORT_ENERGY cut the simulation by a third). On the published entries' plates, seed 0,
    # it reads 0-4.6 points fewer than the long fits alone and 0-1.7 fewer in the ensemble, none of those that
    # the sample can tell (leaderboard/studies/reader_schedule.json, docs/modelling.md).
    "quick": ReaderBudget(max_steps=600, batch_size=48, lr=3e-3, widths_px=(8.0, 200.0), eval_every=100,
                          eval_plates=32, patience=3, bands_per_batch=4),
    "paper": ReaderBudget(max_steps=6000, batch_size=64, lr=1e-3, widths_px=(8.0, 200.0), eval_every=200,
                          eval_plates=128, patience=5, bands_per_batch=4),
}
"""Fine-tuning budget per ``AttackBudget.profile`` (one for each of ``attacks.base.BUDGET_PROFILES``)."""

SUPPORT_ENERGY = 0.995
"""The training plates' patches reach this much of the PSF's light beyond the crop (``psf_support_px``),
not its whole support: on the 87 px co-designed PSFs that is 21-26 px of 43, and up to a third less to simulate."""

VIEWS: tuple[tuple[float, float, float], ...] = (
    (0.0, 0.0, 1.0), (0.02, 0.0, 1.0), (-0.02, 0.0, 1.0), (0.0, 0.0, 1.04), (0.0, 0.0, 0.96),
    (0.0, 0.08, 1.0), (0.0, -0.08, 1.0), (0.03, 0.0, 1.05), (-0.03, 0.0, 0.95))
"""Views of each box read and averaged (x shift and y shift as fractions of the box's width and height,
scale): the crop's sampling grid moves with them. On 200 clean 32 px plates the shipped start read
93.5 % and 93.0 % of two draws with the box alone, 97.0 % and 96.0 % with these nine views."""

_CURVE = "__fit_curve__"  # the fit's curve rides in the cached weights file as a uint8 JSON tensor


def pretrained_key(fmt: str, seed: int = 0) -> dict[str, Any]:
    """The key the pre-trained weights are shipped (and looked up) under."""
    return versioned_key(LearnedReader.name, {"attack": LearnedReader.name, "stage": "pretrained-sharp", "format": fmt,
                                              "width": WIDTH, "budget": PRETRAIN_BUDGET.to_dict(), "seed": seed})


def start_budget(profile: str) -> ReaderBudget:
    """The pre-training a fit runs here when the package ships no start for its plate format: the full one
    for quick and paper, the profile's own small one for smoke and tiny (the full one takes tens of
    minutes on 2 cores)."""
    return BUDGETS[profile] if profile in ("tiny", "smoke") else PRETRAIN_BUDGET


def pack_weights(net: PlateCNN, curve: FitCurve) -> bytes:
    state = {k: v.detach().cpu().contiguous() for k, v in net.state_dict().items()}
    state[_CURVE] = torch.frombuffer(bytearray(json.dumps(curve.to_dict()).encode()), dtype=torch.uint8).clone()
    return save_safetensors(state, metadata={"kind": LearnedReader.name})


def unpack_weights(net: PlateCNN, data: bytes) -> FitCurve | None:
    """Load `pack_weights` bytes into ``net`` (strictly: every tensor, no other); the curve they carry, if any."""
    state = load_safetensors(data)
    curve = state.pop(_CURVE, None)
    net.load_state_dict(state, strict=True)
    return None if curve is None else FitCurve.from_dict(json.loads(bytes(curve.tolist()).decode()))


class LearnedReader(Reader):
    """Reads each given plate box with a CNN fine-tuned on plates simulated through the lens (module docs).

    Args:
        min_width_px: Narrower boxes are not read (the scorer scores none that narrow).
        use_shipped: Start from the package's pre-trained weights (False: pre-train here first).
        use_shipped_fit: Load a fit the package ships for this lens and key (``ship-lens``) instead of
            fine-tuning (False: fine-tune here unless the cache holds the fit).
        fit_seed: Seed of the fit's draws (plates, noise, order). The default 0 makes the fit a function of
            the lens alone, so a fixed lens is fitted once for every run seed (its cache key holds no run
            seed); None: the run's seed (``ctx.seed``), one fit per seed.

    Attributes (after ``fit``): ``curve`` (the fine-tuning's held-out curve, None when loaded from a
    cache written without one), ``trained`` (False: weights came from the cache), ``shipped``.
    """

    name: ClassVar[str] = "learned-reader"
    fit_code: ClassVar[str] = "learned-reader"  # whose code version keys its fits (attacks.training.fit_code)
    hints: ClassVar[frozenset[str]] = frozenset({"plate_boxes"})
    threat_model: ClassVar[ThreatModel] = ThreatModel.LENS_ACCESS
    learns: ClassVar[bool] = True
    # No required field: with no lens (the sharp scenes) it reads with its sharp start (``fit``).
    requires: ClassVar[frozenset[str]] = frozenset()
    # In the standard ensemble (benchmark.runner.defaults.STANDARD_ENSEMBLE); --all-chains adds it too.
    run_by_default: ClassVar[bool] = True
    # What the network reads and is fine-tuned on: the sensor image ("wiener": its Wiener estimate,
    # ``learned-reader-psf``); ``attacks.training.reader_family_training.lens_camera``.
    reads: ClassVar[str] = "sensor"

    def __init__(self, min_width_px: int = 8, use_shipped: bool = True, use_shipped_fit: bool = True,
                 fit_seed: int | None = 0) -> None:
        self.min_width_px = min_width_px
        self.fit_seed = fit_seed
        self.use_shipped = use_shipped
        self.use_shipped_fit = use_shipped_fit
        self.fit_key: dict[str, Any] | None = None
        self.shipped_fit: Shipped | None = None
        self.plate_format = PLATE_FORMAT
        self.net: PlateCNN | None = None
        self.spread_px = 0.0
        self.budget: ReaderBudget | None = None
        self.curve: FitCurve | None = None
        self.trained: bool | None = None
        self.shipped: Shipped | None = None

    def skip_reason(self, ctx: FitContext) -> str | None:
        if ctx.lens is not None and not callable(ctx.lens):
            return ("learned-reader needs a lens that forms sensor images (lens(x, generator=g), as lenses.Lens does) "
                    f"to simulate its training plates; {type(ctx.lens).__name__} does not")
        return None

    def fit(self, ctx: FitContext) -> FitReport:
        """Fine-tune (or load from ``ctx.artifacts``) the reader on plates through ``ctx.lens``; with no
        lens (the sharp scenes) read with the start, pre-trained on sharp plates, as it is."""
        reason = self.skip_reason(ctx)
        if reason is not None:
            raise ValueError(reason)
        self.plate_format = ctx.plate_format
        lens: Any = ctx.lens
        profile = ctx.budget.profile
        seed = ctx.seed if self.fit_seed is None else self.fit_seed
        pretrain_budget = start_budget(profile)
        t0 = time.perf_counter()
        net, start = self._start(seed, pretrain_budget)
        self.budget = self.fine_tune_budget(profile)
        seconds = {"start": time.perf_counter() - t0}
        if lens is None:  # the sharp scenes themselves: the start was trained on sharp plates, read with it
            self.spread_px, self.budget, self.trained = 0.0, None, False
            self.net = net.to(ctx.device).eval()
            return FitReport(stage_seconds=seconds)
        support = SUPPORT_ENERGY if self.reads == "sensor" else None
        camera, self.spread_px, half = lens_camera(lens, self.reads, ctx.device, support)
        key = {"attack": self.name, "budget": self.budget.to_dict(), "lens": lens_key(lens), "format": self.plate_format,
               "start": start, "seed": seed, "keeps": "best-evaluation",
               **({"support_energy": support} if support is not None else {})}
        key = versioned_key(self.fit_code, key)
        self.fit_key = key
        data = None if ctx.artifacts is None else ctx.artifacts.load(self.name, key)
        if data is None and self.use_shipped_fit:  # e.g. the shipped gp lens's fit (``ship-lens``)
            self.shipped_fit = find_shipped(self.name, key)
            data = None if self.shipped_fit is None else self.shipped_fit.data
        if data is not None:
            try:
                self.curve, self.trained = unpack_weights(net, data), False
            except (SafetensorError, RuntimeError, KeyError, ValueError) as exc:
                where = ("the shipped fit " + self.shipped_fit.path.name if self.shipped_fit is not None
                         else f"the cached weights of key {key_text(key)[:120]}")
                log.warning("%s: %s do not load (%s: %s); fitting again and storing the new fit", self.name, where,
                            type(exc).__name__, exc)
                data, self.shipped_fit = None, None
                net, _ = self._start(seed, pretrain_budget)  # a failed load may have overwritten some weights
        if data is None:
            held_out = held_out_set(camera, self.budget, self.spread_px, half, self.plate_format, seed)
            self.curve = train_reader(net, [camera], self.budget, self.spread_px, half, self.plate_format, seed,
                                      held_out)
            self.trained = True
            if ctx.artifacts is not None:
                ctx.artifacts.save(self.name, key, pack_weights(net, self.curve))
        seconds["fine-tune" if self.trained else "load"] = time.perf_counter() - t0 - seconds["start"]
        self.net = net.to(ctx.device).eval()
        return self.report(seconds)

    def fine_tune_budget(self, profile: str) -> ReaderBudget:
        """The per-lens fine-tune's budget for a run profile (``BUDGETS``)."""
        return BUDGETS[profile]

    def report(self, stage_seconds: dict[str, float] | None = None) -> FitReport:
        """The ``FitReport`` of the last fit: its held-out curve (mean accuracy over the width bins) and
        whether it stopped while still rising; empty before a fit or for a fit loaded without a curve."""
        seconds = {} if stage_seconds is None else stage_seconds
        if self.curve is None or not self.curve.steps:
            return FitReport(stage_seconds=seconds)
        curve = ReportedCurve(tuple(self.curve.steps), tuple(self.curve.accuracy), "held-out plate accuracy",
                              self.curve.stopped, self.curve.steps[self.curve.kept])
        return FitReport(curve=curve, still_rising=self.curve.still_rising, stage_seconds=seconds)

    def _start(self, seed: int, pretrain_budget: ReaderBudget) -> tuple[PlateCNN, dict[str, Any]]:
        """The network to fine-tune and what it started from: the shipped pre-trained weights for the
        plate format, else a fresh network pre-trained here on sharp plates (seeded, ``pretrain_budget``)."""
        net = self.build(self.plate_format, seed)
        # The learned reader's own start, also for readers built on it (learned-reader-psf).
        shipped = find_shipped(LearnedReader.name, pretrained_key(self.plate_format)) if self.use_shipped else None
        if shipped is not None:
            unpack_weights(net, shipped.data)
            self.shipped = shipped
            return net, {"shipped": shipped.path.name, "sha256": shipped.provenance["sha256"]}
        curve = pretrain(net, self.plate_format, seed, pretrain_budget)
        return net, {"pretrained_here": {**pretrained_key(self.plate_format, seed), "budget": pretrain_budget.to_dict()},
                     "held_out": curve.accuracy[curve.kept:][:1]}

    @staticmethod
    def build(fmt: str, seed: int) -> PlateCNN:
        """A fresh reader network for plate format ``fmt``, initialised from ``seed``."""
        with torch.random.fork_rng(devices=[]):
            torch.manual_seed(seed)
            return PlateCNN(tuple(len(a) for a in format_alphabets(fmt)), width=WIDTH)

    def read(self, images: Tensor, hints: ReadHints | None = None) -> list[list[PlateRead]]:
        """One read per given plate box at least ``min_width_px`` wide; nothing without boxes."""
        if self.net is None:
            raise RuntimeError(f"{self.name}: call fit(ctx) before read()")
        boxes = [] if hints is None or hints.plate_boxes is None else hints.plate_boxes
        wanted = [(i, tuple(float(v) for v in box)) for i, per_image in enumerate(boxes[:images.shape[0]])
                  for box in per_image if box[2] - box[0] >= self.min_width_px]
        reads: list[list[PlateRead]] = [[] for _ in range(images.shape[0])]
        if not wanted:
            return reads
        device = next(self.net.parameters()).device
        with torch.no_grad():
            images = self.reader_input(images.to(device))
            per_view = [[slot.softmax(dim=1).cpu() / len(VIEWS) for slot in
                         self.net(plate_crops(images, [(i, _moved(box, view)) for i, box in wanted], self.spread_px))]
                        for view in VIEWS]
        probabilities = [sum(views[1:], views[0]) for views in zip(*per_view)]  # per slot, the mean over the views
        alphabets = format_alphabets(self.plate_format)
        for n, (i, box) in enumerate(wanted):
            best = [p[n].max(dim=0) for p in probabilities]
            text = "".join(alphabet[int(b.indices)] for alphabet, b in zip(alphabets, best))
            score = float(torch.stack([b.values for b in best]).prod())
            reads[i].append(PlateRead(text, (box[0], box[1], box[2], box[3]), score))
        return reads

    def reader_input(self, images: Tensor) -> Tensor:
        """What the crops are cut from: the images themselves (``learned-reader-psf`` deconvolves them first)."""
        return images

    def describe(self) -> dict[str, Any]:
        """Budget, plate format, PSF spread and where the start weights came from."""
        described = {**super().describe(), "fit_seed": self.fit_seed, "plate_format": self.plate_format, "spread_px": round(self.spread_px, 3),
                     "budget": None if self.budget is None else self.budget.to_dict(), "trained": self.trained,
                     "recipe": "per-slot CE, label smoothing 0.05, AdamW warm-up then cosine; stops when held-out accuracy flattens"}
        if self.shipped is not None:
            described["shipped_weights"] = self.shipped.describe()
        if self.shipped_fit is not None:
            described["shipped_fit"] = self.shipped_fit.describe()
        return described


def _moved(box: tuple[float, ...], view: tuple[float, float, float]) -> tuple[float, float, float, float]:
    """``box`` (x0, y0, x1, y1) shifted by a view's fractions of its size and scaled about its centre."""
    x0, y0, x1, y1 = box
    dx, dy, scale = view
    w, h = x1 - x0, y1 - y0
    cx, cy = (x0 + x1) / 2 + dx * w, (y0 + y1) / 2 + dy * h
    return cx - scale * w / 2, cy - scale * h / 2, cx + scale * w / 2, cy + scale * h / 2


def pretrain(net: PlateCNN, fmt: str, seed: int, budget: ReaderBudget | None = None) -> FitCurve:
    """Pre-train ``net`` in place on sharp plates (``PRETRAIN_BUDGET`` unless ``budget``): the clean
    renders with white noise of a random level (up to 3 % of full scale, about the shot noise of a
    mid-grey at the default full well), so that the start knows glyphs, not one lens."""
    budget = PRETRAIN_BUDGET if budget is None else budget

    def sharp_camera(x: Tensor, generator: torch.Generator) -> Tensor:
        sigma = 0.03 * torch.rand(x.shape[0], 1, 1, 1, generator=generator)
        return (x + sigma * torch.randn(x.shape, generator=generator)).clamp(0.0, 1.0)

    held_out = held_out_set(None, budget, 0.0, 0, fmt, seed)
    return train_reader(net, [sharp_camera], budget, 0.0, 0, fmt, seed, held_out)
