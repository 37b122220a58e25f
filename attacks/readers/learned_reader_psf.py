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
the sharp-plate start (``learned-reader-sharp-s0``). Nothing is trained per lens: its fit stores the PSF and the gain
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
from attacks.training.psf_restorer_training import psf_inputs
from attacks.training.reader_family_training import FAMILY_BUDGET
from attacks.training.shipped_weights import find_shipped

__all__ = ["LearnedReaderPSF", "family_key"]


def family_key(fmt: str, seed: int = 0, reads: str = "sensor") -> dict[str, Any]:
    """The key a learned reader's family pre-training is shipped (and looked up) under; it continues the
    sharp start. ``reads="wiener"``: ``learned-reader-psf``'s, on Wiener estimates; "sensor":
    ``learned-reader``'s, on the sensor image (``python -m benchmark pretrain-attacker learned-reader --family``)."""
    key = {"attack": LearnedReaderPSF.name if reads == "wiener" else LearnedReader.name, "stage": "pretrained-family",
           "format": fmt, "width": WIDTH, "budget": FAMILY_BUDGET.to_dict(), "family": LensFamily().describe(),
           "start": pretrained_key(fmt, seed), "seed": seed}
    return {**key, "reads": reads} if reads == "wiener" else key


class LearnedReaderPSF(LearnedReader):
    """Reads the Wiener estimate of each image with the sharp-plate reader (module docs)."""

    name: ClassVar[str] = "learned-reader-psf"
    threat_model: ClassVar[ThreatModel] = ThreatModel.LENS_ACCESS
    learns: ClassVar[bool] = True  # its network is trained (on sharp plates, once), not per lens
    requires: ClassVar[frozenset[str]] = frozenset()
    run_by_default: ClassVar[bool] = True

    def __init__(self, min_width_px: int = 8, use_shipped: bool = True, family: bool = True) -> None:
        """``family=False`` reads with the sharp-plate start even where the family pre-training is shipped."""
        super().__init__(min_width_px=min_width_px, use_shipped=use_shipped, use_shipped_fit=False, fit_seed=0)
        self.family = family
        self._otf: OtfCache | None = None
        self._gain: Tensor | None = None

    def fit(self, ctx: FitContext) -> FitReport:
        """Load the family pre-training (else the sharp-plate start) and measure the lens (its PSF and gain);
        nothing is trained here."""
        reason = self.skip_reason(ctx)
        if reason is not None:
            raise ValueError(reason)
        self.plate_format = ctx.plate_format
        t0 = time.perf_counter()
        # Without a lens (the sharp scenes) the sharp-plate start reads: the family pre-training reads clean
        # 32 px plates less well (84 % of 200 against 97 %), having learned Wiener estimates instead.
        family = (find_shipped(self.name, family_key(self.plate_format, reads="wiener"))
                  if self.use_shipped and self.family and ctx.lens is not None else None)
        if family is not None:
            net = self.build(self.plate_format, 0)
            unpack_weights(net, family.data)
            self.shipped = family
        else:
            net, _ = self._start(0, start_budget(ctx.budget.profile))
        self.net = net.to(ctx.device).eval()
        self.spread_px, self.budget, self.trained, self.curve = 0.0, None, False, None
        if ctx.lens is not None:
            self._otf = OtfCache(ctx.lens.psf().detach().cpu())
            self._gain = ctx.lens.gain().detach().cpu()
        return FitReport(stage_seconds={"start": time.perf_counter() - t0})

    def reader_input(self, images: Tensor) -> Tensor:
        """The per-colour Wiener estimate of `images` with the lens's PSF and gain (the images themselves
        without a lens)."""
        if self._otf is None or self._gain is None:
            return images
        return psf_inputs(images.cpu(), self._otf, self._gain)[:, :3].to(images.device)

    def describe(self) -> dict[str, Any]:
        return {**super().describe(), "input": "Wiener estimate with the lens's PSF and gain (psf_inputs)",
                "recipe": "zero-shot: " + ("the family pre-training on Wiener estimates" if self._family() else
                                           "the sharp-plate start") + ", nothing trained per lens"}

    def _family(self) -> bool:
        return self.shipped is not None and self.shipped.provenance.get("kind") == self.name
