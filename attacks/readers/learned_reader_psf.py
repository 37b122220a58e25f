"""``learned-reader-psf``: the learned reader's network reading the Wiener estimate of the known lens.

Threat model: lens access, as ``learned-reader``: the attacker measures the PSF (a point source) and the
gain (a flat field). Instead of training a network per lens to read through the blur, it removes the
blur the one way that knows the PSF: each image is Wiener-deconvolved per colour with the lens's PSF,
at the noise level measured on the image's own Bayer sites (``psf_inputs``, the first stage of
``nafnet-known-psf``), and the network pre-trained on sharp plates (``learned-reader-sharp-s0``) reads
the estimate, given the plate box, as ``learned-reader`` reads (nine views of the box averaged). The crop
needs no margin for the blur (the deconvolved plate is compact), so it is cut around the box itself.

Its network: the package's pre-training across the lens family on Wiener estimates
(``learned-reader-psf-family-s0``: ``python -m benchmark pretrain-attacker learned-reader-psf``, from the
sharp-plate start, on lenses drawn inside the co-design bounds and out of focus, scored on lenses not
drawn; ``attacks.training.reader_family_training``); where the package ships none, and without a lens,
the sharp-plate start (``learned-reader-sharp-s0``). Per lens, the family network is fine-tuned on plates
simulated through the lens and Wiener-deconvolved as a run's are by ``learned-reader-psf-tuned``
(``LearnedReaderPSFTuned``, ``TUNE_BUDGETS``; ``ReaderBudget.eval_start``): the start is scored on the
held-out plates first, and the fine-tune stops as soon as two evaluations in a row have not raised it by a
point, keeping its best evaluation, so a lens the family network already reads as well as it can costs
about 100 steps and keeps the start. That fit is cached per (lens, budget, start weights), one for every
run seed. ``learned-reader-psf`` itself reads zero-shot: its fit stores the PSF and the gain
(milliseconds). Measured against the learned reader fine-tuned per lens on the published entries' own
plates: ``benchmark.studies.psf_reader_study``.
Without a lens (the sharp scenes) it reads the images as they are. Chained after a restorer it would
deconvolve an image that is no longer the sensor's: the standard ensemble reads the sensor image with it.
"""

from __future__ import annotations

import time
from typing import Any, ClassVar

from torch import Tensor

from attacks.backends.real_fft import OtfCache
from attacks.base import FitContext, FitReport, ThreatModel
from attacks.readers.learned_reader import WIDTH, LearnedReader, pretrained_key, start_budget, unpack_weights
from attacks.training.lens_family import LensFamily
from attacks.training.plate_reader_training import ReaderBudget
from attacks.training.psf_restorer_training import psf_inputs
from attacks.training.reader_family_training import FAMILY_BUDGET
from attacks.training.fit_code import versioned_key
from attacks.training.shipped_weights import Shipped, find_shipped
from attacks.networks.plate_cnn import PlateCNN

__all__ = ["LearnedReaderPSF", "LearnedReaderPSFTuned", "TUNE_BUDGETS", "family_key"]

TUNE_BUDGETS: dict[str, ReaderBudget] = {
    "tiny": ReaderBudget(max_steps=2, batch_size=4, lr=1e-4, widths_px=(24.0, 64.0), eval_every=1, eval_plates=2,
                         patience=1, eval_start=True),
    "smoke": ReaderBudget(max_steps=10, batch_size=16, lr=3e-4, widths_px=(8.0, 200.0), eval_every=5, eval_plates=8,
                          patience=1, bands_per_batch=4, eval_start=True),
    "quick": ReaderBudget(max_steps=400, batch_size=48, lr=3e-4, widths_px=(8.0, 200.0), eval_every=50,
                          eval_plates=32, patience=2, bands_per_batch=4, eval_start=True),
    "paper": ReaderBudget(max_steps=2000, batch_size=64, lr=3e-4, widths_px=(8.0, 200.0), eval_every=100,
                          eval_plates=128, patience=3, bands_per_batch=4, eval_start=True),
}
"""The per-lens fine-tune from the family network (module docs), per ``AttackBudget.profile``."""


def family_key(fmt: str, seed: int = 0, reads: str = "sensor") -> dict[str, Any]:
    """The key a learned reader's family pre-training is shipped (and looked up) under; it continues the
    sharp start. ``reads="wiener"``: ``learned-reader-psf``'s, on Wiener estimates; "sensor":
    ``learned-reader``'s, on the sensor image (``python -m benchmark pretrain-attacker learned-reader --family``)."""
    attack = LearnedReaderPSF.name if reads == "wiener" else LearnedReader.name
    key = {"attack": attack, "stage": "pretrained-family",
           "format": fmt, "width": WIDTH, "budget": FAMILY_BUDGET.to_dict(), "family": LensFamily().describe(),
           "start": pretrained_key(fmt, seed), "seed": seed}
    return versioned_key(attack, {**key, "reads": reads} if reads == "wiener" else key)


class LearnedReaderPSF(LearnedReader):
    """Reads the Wiener estimate of each image with the sharp-plate reader (module docs)."""

    name: ClassVar[str] = "learned-reader-psf"
    fit_code: ClassVar[str] = "learned-reader-psf"
    threat_model: ClassVar[ThreatModel] = ThreatModel.LENS_ACCESS
    learns: ClassVar[bool] = True  # its network is trained (on sharp plates, once), not per lens
    requires: ClassVar[frozenset[str]] = frozenset()
    run_by_default: ClassVar[bool] = True

    reads: ClassVar[str] = "wiener"

    def __init__(self, min_width_px: int = 8, use_shipped: bool = True, family: bool = True,
                 fine_tune: bool = False) -> None:
        """``family=False`` reads with the sharp-plate start even where the family pre-training is shipped;
        ``fine_tune=True`` fine-tunes the family network on the lens (``learned-reader-psf-tuned``)."""
        super().__init__(min_width_px=min_width_px, use_shipped=use_shipped, use_shipped_fit=False, fit_seed=0)
        self.family = family
        self.fine_tune = fine_tune
        self._family_weights: Shipped | None = None
        self._otf: OtfCache | None = None
        self._gain: Tensor | None = None

    def fit(self, ctx: FitContext) -> FitReport:
        """Load the family pre-training (else the sharp-plate start), fine-tune it on the lens unless
        ``fine_tune=False`` (or the cache holds the fit), and measure the lens (its PSF and gain)."""
        reason = self.skip_reason(ctx)
        if reason is not None:
            raise ValueError(reason)
        self.plate_format = ctx.plate_format
        # Without a lens (the sharp scenes) the sharp-plate start reads: the family pre-training reads clean
        # 32 px plates less well (84 % of 200 against 97 %), having learned Wiener estimates instead.
        self._family_weights = (find_shipped(LearnedReaderPSF.name, family_key(self.plate_format, reads="wiener"))
                                if self.use_shipped and self.family and ctx.lens is not None else None)
        if self._family_weights is not None and self.fine_tune:
            report = super().fit(ctx)  # from the family network (``_start``), on Wiener estimates (``reads``)
        else:
            t0 = time.perf_counter()
            net, _ = self._start(0, start_budget(ctx.budget.profile))
            self.net = net.to(ctx.device).eval()
            self.spread_px, self.budget, self.trained, self.curve = 0.0, None, False, None
            report = FitReport(stage_seconds={"start": time.perf_counter() - t0})
        if ctx.lens is not None:
            self._otf = OtfCache(ctx.lens.psf().detach().cpu())
            self._gain = ctx.lens.gain().detach().cpu()
        return report

    def fine_tune_budget(self, profile: str) -> ReaderBudget:
        return TUNE_BUDGETS[profile]

    def _start(self, seed: int, pretrain_budget: ReaderBudget) -> tuple[PlateCNN, dict[str, Any]]:
        """The family network where it is shipped and wanted (``fit``), else the sharp-plate start."""
        if self._family_weights is None:
            return super()._start(seed, pretrain_budget)
        net = self.build(self.plate_format, 0)
        unpack_weights(net, self._family_weights.data)
        self.shipped = self._family_weights
        return net, {"shipped": self._family_weights.path.name, "sha256": self._family_weights.provenance["sha256"]}

    def reader_input(self, images: Tensor) -> Tensor:
        """The per-colour Wiener estimate of `images` with the lens's PSF and gain (the images themselves
        without a lens)."""
        if self._otf is None or self._gain is None:
            return images
        return psf_inputs(images.cpu(), self._otf, self._gain)[:, :3].to(images.device)

    def describe(self) -> dict[str, Any]:
        if not self._family():
            recipe = "zero-shot: the sharp-plate start, nothing trained per lens"
        elif self.budget is None:
            recipe = "zero-shot: the family pre-training on Wiener estimates, nothing trained per lens"
        else:
            recipe = ("the family pre-training on Wiener estimates, fine-tuned on this lens's Wiener estimates until "
                      "its held-out accuracy flattens; the best evaluation kept (step 0: the family network)")
        return {**super().describe(), "input": "Wiener estimate with the lens's PSF and gain (psf_inputs)",
                "recipe": recipe}

    def _family(self) -> bool:
        return self.shipped is not None and self.shipped.provenance.get("kind") == LearnedReaderPSF.name


class LearnedReaderPSFTuned(LearnedReaderPSF):
    """``learned-reader-psf`` fine-tuned on the lens from its family network (module docs); not in the
    standard ensemble (``benchmark.runner.defaults``): run it with ``--attack learned-reader-psf-tuned``."""

    name: ClassVar[str] = "learned-reader-psf-tuned"
    run_by_default: ClassVar[bool] = False

    def __init__(self, min_width_px: int = 8, use_shipped: bool = True, family: bool = True) -> None:
        super().__init__(min_width_px=min_width_px, use_shipped=use_shipped, family=family, fine_tune=True)
