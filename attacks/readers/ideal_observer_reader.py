"""``ideal-observer``: read each plate by maximum likelihood over whole strings, knowing the lens.

The attacker has the camera (PSF per channel, electrons per unit radiance, read noise and ADC), the
plate format and the font and layout (the scenes' own renderer, ``common.plate_render``),
and the true plate boxes (``ReadHints.plate_boxes``, like ``lpdr-oracle``'s vehicle boxes). For
each box it recovers the raw electrons from the sensor image (the demosaic keeps each raw value at
its own site) and scores a candidate string by its Gaussian log-likelihood: the string is rendered
at the box's size, blurred with the PSF, converted to electrons, and fitted to the observed sites
of each colour by a gain, a uniform surround and an offset (the plate's tint and exposure and the
scene around the plate are unknown: the profile likelihood maximises over them; a surround that is
not uniform is a model error this reader lives with); the noise variance per site is the shot +
read + 10-bit rounding variance at the observed level.

Search. A dynamic programme over neighbouring characters is exact only when each glyph's position
does not depend on the other characters. The plates are centred in a proportional font (and
shrunk when too wide), so every glyph's position depends on the advance widths of all the others:
the likelihood couples every character with every other, too wide for a DP. So the search is a
beam search over whole strings, in sweeps over the positions: at each position every value is
substituted into each beam string and scored with its exact full rendering, and the `beam` best
strings are kept; sweeps repeat until a whole sweep leaves the best string unchanged (at most
`max_sweeps`). The search runs from three starts (narrow, medium and wide glyphs everywhere, i.e.
three layouts), from each with every beam width of `beams` in turn, and the best string found wins: one
start alone gets caught where fixing one glyph moves all the others, and a wider beam is not a wider
search (its sweeps take other paths: on a clean test plate beam 6 stopped at a string far less likely
than the true one, which beams 3, 4 and 8 found); the strings are scored once and shared, so the widths
together find a string at least as likely as each width alone. Whether the plate has the EU band is
decided first, by the best likelihood of the starting strings with and without it. Cost: about
3 x beam x 134 renderings per sweep and width. The boxes of one ``read_batches`` call (every batch
of it: a run hands the cascade's windows in one call) are searched in `workers` forked processes (one torch
thread each; default: the CPUs this process may use), the widest first: the rendering holds the GIL, so
threads do not help; a box's read does not depend on which process searched it, nor when. The default
search (beams 3 then 6, at most 6 sweeps) against beam 3 with 4 sweeps on the same plates, and what each
costs: leaderboard/studies/ideal_observer_beam.json (benchmark.studies.observer_beam_study).
"""

from __future__ import annotations

import multiprocessing
import os
import sys
from collections.abc import Iterable
from typing import Any, ClassVar

import numpy as np
import torch
from torch import Tensor

from attacks.base import FitContext, FitReport, PlateRead, ReadHints, Reader, ThreatModel
from common.plate_render import PLATE_FORMAT, format_alphabets, plate_font, render_plate
from lenses.raw_likelihood import BoxBlur
from lenses.sensor import bayer_masks

__all__ = ["IdealObserverReader"]

REFERENCE_BACKGROUND = (236, 236, 228)  # rendering colour; the per-channel gain absorbs the true tint
# What the forked workers of one read call search in: (the reader, the raw electron images of each batch);
# set only while that call's pool runs (the children inherit it by fork).
_FORKED: tuple[IdealObserverReader, list[Tensor]] | None = None


class IdealObserverReader(Reader):
    """Maximum-likelihood plate reader with the lens, the font and the true plate boxes (module docstring).

    Args:
        beams: the beam widths searched in turn from each start (strings kept per round; 1: coordinate ascent).
        max_sweeps: at most this many sweeps over the positions, per width and start.
        min_width_px: narrower boxes are not read (nothing to read, and the runner scores none).
        workers: processes that search the boxes of a read call (None: the CPUs this process may use;
            1: in this process). Results do not depend on it.
    """

    name: ClassVar[str] = "ideal-observer"
    hints: ClassVar[frozenset[str]] = frozenset({"plate_boxes"})
    threat_model: ClassVar[ThreatModel] = ThreatModel.LENS_ACCESS
    requires: ClassVar[frozenset[str]] = frozenset({"lens"})
    # Seconds per plate: not in the full cross product; the standard ensemble runs it as a cascade, on the
    # plates no other chain read (benchmark.runner.cascade); --attack ideal-observer reads every plate.
    run_by_default: ClassVar[bool] = False

    def __init__(self, beams: tuple[int, ...] = (3, 6), max_sweeps: int = 6, min_width_px: int = 8,
                 workers: int | None = None) -> None:
        if not beams or min(beams) < 1 or max_sweeps < 1:
            raise ValueError(f"beams (one width or more) and max_sweeps must be >= 1, got {beams}, {max_sweeps}")
        if workers is not None and workers < 1:
            raise ValueError(f"workers must be >= 1 (or None: the CPUs this process may use), got {workers}")
        self.workers = workers
        self.beams = tuple(int(b) for b in beams)
        self.max_sweeps = max_sweeps
        self.min_width_px = min_width_px
        self.plate_format = PLATE_FORMAT
        self._camera: dict[str, Any] | None = None

    def skip_reason(self, ctx: FitContext) -> str | None:
        if ctx.lens is None:
            return "ideal-observer models the lens's image formation, and this context has no lens (FitContext.lens)"
        if getattr(getattr(ctx.lens, "spec", None), "sensor", None) is None:
            return ("ideal-observer needs the sensor's constants (lens.spec.sensor: full well, read noise, ADC bits) "
                    "to model its noise, and this lens has none")
        return None

    def fit(self, ctx: FitContext) -> FitReport:
        """Take the lens's PSF, gain and sensor constants, and the scenes' plate format (``ctx.plate_format``)."""
        lens = ctx.lens
        if lens is None:  # skip_reason says so; fit may be called without asking it
            raise ValueError(self.skip_reason(ctx))
        sensor = lens.spec.sensor
        with torch.no_grad():
            psf = lens.psf().detach().to(torch.float64).cpu()
            gain = lens.gain().detach().to(torch.float64).cpu()
        self.plate_format = ctx.plate_format
        format_alphabets(self.plate_format)  # validates it
        levels = 2**sensor.adc_bits - 1
        self._camera = {"psf": psf, "electrons_per_unit": gain * sensor.full_well_e,
                        "read_noise_e": sensor.read_noise_e, "electrons_per_level": sensor.full_well_e / levels,
                        "levels": levels}
        return FitReport()

    def describe(self) -> dict[str, Any]:
        return {**super().describe(), "beams": list(self.beams), "max_sweeps": self.max_sweeps,
                "min_width_px": self.min_width_px, "plate_format": self.plate_format}

    def read(self, images: Tensor, hints: ReadHints | None = None) -> list[list[PlateRead]]:
        """Read every box of ``hints.plate_boxes``; see ``Reader.read``."""
        return self.read_batches([(images, hints)])[0]

    def read_batches(self, batches: Iterable[tuple[Tensor, ReadHints | None]]) -> list[list[list[PlateRead]]]:
        """``read`` of each batch, the boxes of every batch searched in one pool of workers (the widest
        first), so that no worker idles between batches (a batch of one window would leave all but one
        waiting); a box's read does not depend on where or when it was searched."""
        if self._camera is None:
            raise RuntimeError("ideal-observer must be fitted (fit(ctx) with ctx.lens) before reading")
        raws: list[Tensor] = []
        jobs: list[tuple[int, int, tuple[int, int, int, int]]] = []  # (batch, image, box)
        outs: list[list[list[PlateRead]]] = []
        for b, (images, hints) in enumerate(batches):
            raw, boxes = self._boxes(images, hints)
            raws.append(raw)
            jobs += [(b, i, box) for i, box in boxes]
            outs.append([[] for _ in range(images.shape[0])])
        for (b, i, box), (text, score) in zip(jobs, self._search_boxes(raws, jobs)):
            outs[b][i].append(PlateRead(text, tuple(float(v) for v in box), score))  # type: ignore[arg-type]
        return outs

    def _boxes(self, images: Tensor, hints: ReadHints | None) -> tuple[Tensor, list[tuple[int, tuple[int, int, int, int]]]]:
        """One batch's raw electron images (B, H, W) and its boxes to search: (image, box), in order."""
        if images.ndim != 4 or images.shape[1] != 3:
            raise ValueError(f"images must be (B, 3, H, W), got shape {tuple(images.shape)}")
        boxes = None if hints is None else hints.plate_boxes
        if boxes is None or len(boxes) != images.shape[0]:
            raise ValueError("ideal-observer needs ReadHints(plate_boxes=...) with one list of true plate boxes "
                             f"per image ({images.shape[0]} images); got {None if boxes is None else len(boxes)}")
        assert self._camera is not None
        raw = self._raw_electrons(images.detach().to(torch.float64).cpu(), self._camera)
        jobs = []
        for i, image_boxes in enumerate(boxes):
            for box in image_boxes:
                x0, y0, x1, y1 = (int(round(v)) for v in box)
                if x1 - x0 >= self.min_width_px and y1 - y0 >= 2:
                    jobs.append((i, (x0, y0, x1, y1)))
        return raw, jobs

    def _worker_count(self, n_jobs: int) -> int:
        """Processes for `n_jobs` boxes: `workers` (None: the CPUs this process may use), at most one a box,
        and 1 where fork is not the platform's safe default (Linux only)."""
        if not sys.platform.startswith("linux"):
            return 1
        wanted = self.workers if self.workers is not None else len(os.sched_getaffinity(0))
        return max(1, min(wanted, n_jobs))

    def _search_boxes(self, raws: list[Tensor], jobs: list[tuple[int, int, tuple[int, int, int, int]]]
                      ) -> list[tuple[str, float]]:
        """``read_box`` of every job (batch, image, box) of the raw electron batches `raws`, in this process or
        in forked workers (one torch thread each; the widest boxes handed out first, so that the last to
        finish is a short one), in the jobs' order; the pool is closed and its processes reaped before this
        returns."""
        n = self._worker_count(len(jobs))
        if n <= 1:
            return [self.read_box(raws[b][i], box) for b, i, box in jobs]
        order = sorted(range(len(jobs)), key=lambda j: (-(jobs[j][2][2] - jobs[j][2][0]), j))
        global _FORKED
        _FORKED = (self, raws)
        try:
            pool = multiprocessing.get_context("fork").Pool(n, initializer=torch.set_num_threads, initargs=(1,))
            try:
                found = pool.map(_read_forked, [jobs[j] for j in order], chunksize=1)
            finally:
                pool.close()
                pool.join()
        finally:
            _FORKED = None
        out: list[tuple[str, float]] = [("", 0.0)] * len(jobs)
        for j, result in zip(order, found):
            out[j] = result
        return out

    @staticmethod
    def _raw_electrons(images: Tensor, cam: dict[str, Any]) -> Tensor:
        """(B, H, W) raw electrons: each site's own channel of the demosaicked image, back in electrons."""
        masks = bayer_masks(images.shape[-2], images.shape[-1], dtype=torch.float64)
        digital = torch.round((images * masks).sum(1) * cam["levels"])
        return digital * cam["electrons_per_level"]

    def read_box(self, electrons: Tensor, box: tuple[int, int, int, int]) -> tuple[str, float]:
        """The maximum-likelihood string in one box of a raw electron image (H, W), and a score in (0, 1]:
        the posterior of the best string against the other strings scored."""
        x0, y0, x1, y1 = box
        observed = electrons[y0:y1, x0:x1].reshape(-1)
        cam = self._camera
        assert cam is not None
        variance = observed.clamp(min=0) + cam["read_noise_e"] ** 2 + cam["electrons_per_level"] ** 2 / 12
        scorer = _Scorer(cam, (x1 - x0, y1 - y0), (y0, x0), observed, 1.0 / variance)
        alphabets = format_alphabets(self.plate_format)
        seen: dict[str, float] = {}
        starts = _starting_strings(alphabets)
        band = bool(scorer.score(starts, True).max() > scorer.score(starts, False).max())
        for start in starts:
            for beam in self.beams:
                self._search(scorer, alphabets, start, band, seen, beam)
        best = max(seen, key=seen.__getitem__)
        values = torch.tensor(list(seen.values()), dtype=torch.float64)
        return best, float(torch.softmax(values, 0).max())

    def _search(self, scorer: _Scorer, alphabets: list[str], start: str, band: bool, seen: dict[str, float],
                width: int) -> None:
        """Beam sweeps of `width` strings from `start` (module docstring); every scored string lands in `seen`."""
        if start not in seen:
            seen[start] = float(scorer.score([start], band)[0])
        beam = [start]
        for _ in range(self.max_sweeps):
            best_before = beam[0]
            for i, alphabet in enumerate(alphabets):
                pool = sorted({s[:i] + a + s[i + 1:] for s in beam for a in alphabet})
                fresh = [s for s in pool if s not in seen]
                if fresh:
                    seen.update(zip(fresh, scorer.score(fresh, band).tolist()))
                beam = sorted(pool, key=seen.__getitem__, reverse=True)[:width]
            if beam[0] == best_before:
                break


def _read_forked(job: tuple[int, int, tuple[int, int, int, int]]) -> tuple[str, float]:
    """One box's read in a forked worker of ``IdealObserverReader._search_boxes``."""
    assert _FORKED is not None, "a worker of _search_boxes reads only inside its pool"
    reader, raws = _FORKED
    b, i, box = job
    return reader.read_box(raws[b][i], box)


def _starting_strings(alphabets: list[str]) -> list[str]:
    """Three starts: every position at its narrowest, median and widest glyph (by advance width).

    The layout of the plate (centred, proportional) is set by the sum of the advance widths, so
    searches from a narrow, a medium and a wide layout reach the optimum from different sides.
    """
    font = plate_font(64)
    ranked = [sorted(a, key=lambda ch: (font.getlength(ch), ch)) for a in alphabets]
    return ["".join(r[k(len(r))] for r in ranked) for k in (lambda n: 0, lambda n: n // 2, lambda n: n - 1)]


class _Scorer:
    """Profile log-likelihood of candidate strings for one box (gain and offset fitted per colour)."""

    def __init__(self, cam: dict[str, Any], size: tuple[int, int], origin: tuple[int, int], observed: Tensor,
                 weight: Tensor) -> None:
        self.cam, self.size, self.origin = cam, size, origin
        self.y, self.w = observed, weight
        w, h = size
        self._blur = BoxBlur(cam["psf"], cam["electrons_per_unit"], (h, w), origin)
        self.channel = self._blur.masks.reshape(3, -1).argmax(0)  # each site's colour, in the box's Bayer phase
        # The blurred box indicator: how much of each site's light comes from the box.
        self._footprint = self._blurred(torch.ones(1, 3, h, w, dtype=torch.float64))[0]

    def score(self, texts: list[str], band: bool, chunk: int = 32) -> Tensor:
        """Log-likelihood (N,) of each text, up to a constant shared by all texts of this box."""
        return torch.cat([self._score(texts[i:i + chunk], band) for i in range(0, len(texts), chunk)])

    def _blurred(self, radiance: Tensor) -> Tensor:
        """Electrons (N, P) over the box of patches (N, 3, h, w) on a black surround, in the box's Bayer phase."""
        return self._blur(radiance).reshape(radiance.shape[0], -1)

    def _score(self, texts: list[str], band: bool) -> Tensor:
        w, h = self.size
        plates = np.stack([np.asarray(render_plate(t, (w, h), REFERENCE_BACKGROUND, band)) for t in texts])
        plate = self._blurred(torch.from_numpy(plates.astype(np.float64) / 255).permute(0, 3, 1, 2))
        total = torch.zeros(len(texts), dtype=torch.float64)
        for c in range(3):
            sites = self.channel == c
            y, wt = self.y[sites], self.w[sites]
            # y ~ a t + b footprint + offset: plate gain (tint, exposure), the unknown surround, and the
            # surround's level; weighted least squares per text, residual from the normal equations.
            design = torch.stack([plate[:, sites], self._footprint[sites].expand(len(texts), -1),
                                  torch.ones(len(texts), int(sites.sum()), dtype=torch.float64)], -1)
            design = design / design.abs().amax(1, keepdim=True).clamp(min=1e-12)  # columns of order 1
            normal = torch.einsum("npi,p,npj->nij", design, wt, design)
            rhs = torch.einsum("npi,p,p->ni", design, wt, y)
            # A relative ridge keeps the solve defined where a column is (nearly) collinear with another
            # (a PSF much wider than the box makes the footprint almost constant).
            normal = normal + 1e-10 * torch.diag_embed(normal.diagonal(dim1=1, dim2=2))
            coef = torch.linalg.solve(normal, rhs)
            total -= 0.5 * ((wt * y * y).sum() - (coef * rhs).sum(-1))
        return total
