"""The ideal observer that is not told what no attacker can know: the marginalised (tighter) ceiling.

The genie's ceiling (`ceiling.py`) is the ideal observer of a signal known exactly but for its
characters: it is told each plate's exact position, size and exposure. This one is the ideal observer
of a signal known only statistically (Barrett and Myers): the nuisances of a `NuisancePrior` (the
plate's position in both axes, sub-pixel and RGGB parity; its width within the width bin; its
exposure) are unknown, drawn independently of the characters from the prior, and the likelihood of a
hypothesis a is the mixture over them,

    p(y | a) = E_theta p(y | a, theta).

What stays known, as in the genie: the format, font and renderer, the plate's colour, EU band and
surround (`PlateModel`), the lens's PSF, the sensor's gain and read noise, and (per block) the other
characters. Knowing more never hurts an optimal observer, so the ceiling stays an upper bound on every
attacker who knows at most that much and faces plates whose unknown nuisances follow the prior; the
colour and surround are kept known because a plate's hundreds of background photo-electrons pin them
far more tightly than the characters need (a bound that knows them is looser, never wrong).

Monte Carlo over the nuisances (the estimator is itself a bound). For each plate, M nuisance points
S = {theta_1..theta_M} are drawn (each marginally from the prior: a scrambled Sobol set), shared by the
hypotheses; the truth is hypothesis a with nuisance theta_J, J uniform over the M points, and the
observer computes

    P(a | y, S) = sum_m p(y | a, theta_m) / sum_a' sum_m p(y | a', theta_m).

That is the exact posterior of an observer told the set S that holds the true nuisance: side
information, so its accuracy E[max_a P(a | y, S)] bounds the marginalised observer's (M -> infinity)
from above for every M; M = 1 is the genie told one random nuisance, and M + 1 points are at most as
informative as M (drop a point known to be false and M remain). The ceiling falls with M towards the
limit. From below, the same mixture rule applied to observations whose nuisance is drawn afresh
(not one of the M points) is a decision rule an attacker who knows the prior can run, so its hit rate
(`rule_*`) is at or below the limit. [rule, ceiling] brackets the limit at every M; `convergence`
tabulates both against M. Where the data pin the nuisances far more tightly than the prior spreads
them, the M-point observer picks out the true point and the ceiling falls slowly with M while the rule
(whose points all miss the truth) stays low: the curve shows it. A discrete prior (position and width
on the pixel grid, exposure known) is averaged over its whole support instead (`NuisancePrior.exhaustive`):
S is then every point, it tells the observer nothing, and the ceiling is the marginalised observer's
itself, with Monte-Carlo error only over plates and noise (`rule_*` then estimates the same accuracy
by hit rate).

Per block and plate as in the genie: per-character ceilings c_i with every other character revealed,
and (`pair`) the first two letters read jointly, the plate bound the least of them. The pair's 676
hypotheses at M points each are scored on a random subset of true hypotheses (`pair_truths`), an
unbiased estimate of the same ceiling; its rule is not computed. The plate texts and the observation noise come from the
genie's random stream (the same seed draws the same plates), the nuisance points, the true nuisance's
index and the fresh-nuisance observations from a second stream: with the prior collapsed to the genie's
point the curve is the genie's (`ceiling_curves(..., pair=None)`) to rounding.

Where the synthetic scenes differ from the default prior (each stated, with its direction): they paste
plates on the pixel grid (integer corner and width; `NuisancePrior("pixel-grid", "pixel-grid")` is their
own prior, the continuous one is a real camera's); their widths within a bin fall off towards its upper
end (more distant plates), so a uniform width favours the observer; they draw the colour (white or
yellow), the EU band and the haze tint, left known here. The "above the ceiling" failure of a reader
therefore stays against the genie's proven bound; a reader above this one is reported, naming it.
"""

from __future__ import annotations

import dataclasses
import math
import time

import numpy as np
import torch

from benchmark.results.observer.ceiling import Camera, CeilingCurve, PlateModel, Precision, _interval
from benchmark.results.observer.nuisance import Nuisance, NuisancePrior, canvas_size, draw_points, nuisance_means, support
from benchmark.results.plate_scoring import WIDTH_BINS_PX
from common.plate_render import format_alphabets, random_plate_text
from lenses.lens import Lens
from lenses.raw_likelihood import draw_statistics, log_likelihoods

NUISANCE_STREAM = 1  # the nuisance generator is default_rng((seed, NUISANCE_STREAM))
DEFAULT_PRIOR = NuisancePrior()


def mixture_accuracy(means_e: torch.Tensor, fresh_e: torch.Tensor | None, read_noise_e: float, frames: int,
                     noise_draws: int, rng: np.random.Generator, nuisance_rng: np.random.Generator
                     ) -> tuple[float, float]:
    """(ceiling, rule) of the |A|-ary test between hypotheses whose means_e (A, M, P) are known only up to
    one of M nuisance points (module docstring), uniform priors on both.

    ceiling: E max_a P(a | y, S) over `noise_draws` observations per hypothesis, each with its true
    nuisance J uniform over the M points (the noise from `rng`, J from `nuisance_rng`). rule: the hit rate
    of the mixture's ML decision on observations of fresh_e (A, D, P), each hypothesis at D nuisance
    points drawn afresh (noise from `nuisance_rng`); NaN when fresh_e is None.
    """
    n_hyp, n_pts, _ = means_e.shape
    flat = means_e.reshape(n_hyp * n_pts, -1)
    varying = (flat.max(0).values - flat.min(0).values) > 0
    if not varying.any():  # identical hypotheses at every point: the posterior is uniform
        return 1.0 / n_hyp, 1.0 / n_hyp
    hyps = flat[:, varying]
    truth = torch.arange(n_hyp).repeat_interleave(noise_draws)
    point = torch.from_numpy(nuisance_rng.integers(n_pts, size=len(truth)))
    s1, s2 = draw_statistics(means_e[truth, point][:, varying], read_noise_e, frames, rng)
    posterior = _posterior(s1, s2, frames, hyps, n_hyp, n_pts, read_noise_e)
    ceiling = float(posterior.max(-1).values.mean())
    if fresh_e is None:
        return ceiling, math.nan
    fresh_truth = torch.arange(n_hyp).repeat_interleave(fresh_e.shape[1])
    f1, f2 = draw_statistics(fresh_e.reshape(-1, fresh_e.shape[-1])[:, varying], read_noise_e, frames, nuisance_rng)
    fresh = _posterior(f1, f2, frames, hyps, n_hyp, n_pts, read_noise_e)
    best = fresh.max(-1, keepdim=True).values
    ties = fresh == best
    hits = ties[torch.arange(len(fresh_truth)), fresh_truth].double() / ties.sum(-1)
    return ceiling, float(hits.mean())


def _posterior(s1: torch.Tensor, s2: torch.Tensor, frames: int, hyps: torch.Tensor, n_hyp: int, n_pts: int,
               read_noise_e: float) -> torch.Tensor:
    """P(a | y, S) (N, A): the likelihood averaged over the M points of each hypothesis, normalised."""
    loglik = log_likelihoods(s1, s2, frames, hyps, read_noise_e).reshape(-1, n_hyp, n_pts)
    return torch.softmax(torch.logsumexp(loglik, -1) - math.log(n_pts), dim=-1)


def _block_texts(text: str, position: int, fmt: str) -> list[str]:
    return [text[:position] + c + text[position + 1:] for c in format_alphabets(fmt)[position]]


def marginal_position_accuracies(camera: Camera, width_px: int, width_high_px: float, frames: tuple[int, ...],
                                 model: PlateModel, prior: NuisancePrior, n_plates: int, noise_draws: int,
                                 rng: np.random.Generator, nuisance_rng: np.random.Generator,
                                 pair: tuple[int, int] | None = None, pair_truths: int = 64) -> np.ndarray:
    """(n_plates, len(frames), L [+ 1], 2) per-plate (ceiling, rule) estimates of each position's
    marginalised c_i at one width bin [width_px, width_high_px), and of the pair's c_pair as a last
    column when `pair` is given (`pair_accuracy`; its rule NaN); the M points are shared by a plate's blocks."""
    height_of = model.height_px
    canvas = canvas_size(prior, width_px, width_high_px, model.aspect, height_of)
    n_pos = len(model.fmt)
    out = np.full((n_plates, len(frames), n_pos + (pair is not None), 2), np.nan)
    for j in range(n_plates):
        text = random_plate_text(rng, model.fmt)
        points = (support(prior, width_px, width_high_px, height_of) if prior.exhaustive
                  else draw_points(prior, width_px, width_high_px, model.aspect, prior.points, nuisance_rng, height_of))
        for i in range(n_pos):
            texts = _block_texts(text, i, model.fmt)
            means = nuisance_means(camera, texts, points, canvas, model, prior.on_grid)
            fresh = torch.stack([nuisance_means(camera, [t], _fresh(prior, width_px, width_high_px, model,
                                                                     noise_draws, nuisance_rng),
                                                canvas, model, prior.on_grid)[0] for t in texts])
            for n, t in enumerate(frames):
                out[j, n, i] = mixture_accuracy(means, fresh, camera.read_noise_e, t, noise_draws, rng, nuisance_rng)
        if pair is not None:
            out[j, :, n_pos, 0] = pair_accuracy(camera, text, pair, frames, model, prior, points, canvas, pair_truths,
                                                rng, nuisance_rng)
    return out


def pair_accuracy(camera: Camera, text: str, pair: tuple[int, int], frames: tuple[int, ...], model: PlateModel,
                  prior: NuisancePrior, points: list[Nuisance], canvas: tuple[int, int], truths: int,
                  rng: np.random.Generator, nuisance_rng: np.random.Generator, chunk: int = 26) -> np.ndarray:
    """(len(frames),) the M-point ceiling of reading the positions `pair` jointly (every other character
    revealed): E max_a P(a | y, S) over `truths` observations, each of a hypothesis and a point drawn
    uniformly (an unbiased estimate with fewer observations than the |A|^2 hypotheses). The hypotheses'
    means are computed `chunk` texts at a time and every pixel of the canvas kept (no mask across chunks)."""
    alphabets = format_alphabets(model.fmt)
    texts = []
    for a in alphabets[pair[0]]:
        for b in alphabets[pair[1]]:
            chars = list(text)
            chars[pair[0]], chars[pair[1]] = a, b
            texts.append("".join(chars))
    n_pts = len(points)
    truth = nuisance_rng.integers(len(texts), size=truths)
    point = nuisance_rng.integers(n_pts, size=truths)
    truth_means = torch.cat([nuisance_means(camera, [texts[a]], [points[m]], canvas, model, prior.on_grid)[0]
                             for a, m in zip(truth, point)])
    stats = [draw_statistics(truth_means, camera.read_noise_e, t, rng) for t in frames]
    loglik: list[list[torch.Tensor]] = [[] for _ in frames]
    for start in range(0, len(texts), chunk):
        means = nuisance_means(camera, texts[start:start + chunk], points, canvas, model, prior.on_grid)
        flat = means.reshape(-1, means.shape[-1])
        for n, (t, (s1, s2)) in enumerate(zip(frames, stats)):
            ll = log_likelihoods(s1, s2, t, flat, camera.read_noise_e).reshape(truths, -1, n_pts)
            loglik[n].append(torch.logsumexp(ll, -1) - math.log(n_pts))
    return np.array([float(torch.softmax(torch.cat(ll, -1), -1).max(-1).values.mean()) for ll in loglik])


def _fresh(prior: NuisancePrior, width_px: int, width_high_px: float, model: PlateModel, n: int,
           nuisance_rng: np.random.Generator) -> list[Nuisance]:
    return draw_points(prior, width_px, width_high_px, model.aspect, n, nuisance_rng, model.height_px)


def bin_highs(widths_px: list[int], edges_px: tuple[int, ...] = WIDTH_BINS_PX) -> list[float]:
    """Each tabulated width's bin end: the next tabulated width or the next edge of the plate-scoring bins
    (`edges_px`), whichever comes first; past the last edge, 1.5 x the width."""
    nexts = [*widths_px[1:], math.inf]
    return [float(min(n, next((e for e in edges_px if e > w), 1.5 * w))) for w, n in zip(widths_px, nexts)]


def marginal_ceiling_curves(lens: Lens, widths_px: tuple[int, ...] | list[int],
                            frames: tuple[int, ...] = (1,), model: PlateModel = PlateModel(),
                            prior: NuisancePrior = DEFAULT_PRIOR, seed: int = 0, noise_draws: int = 2,
                            precision: Precision = Precision(),
                            width_high_px: list[float] | None = None, pair: tuple[int, int] | None = None,
                            pair_until: float = 0.10, pair_truths: int = 64) -> list[CeilingCurve]:
    """One `CeilingCurve` per frame count of the marginalised ceiling (module docstring) through `lens`.

    Tabulated width w_k stands for the bin [w_k, width_high_px[k]) (default `bin_highs`: the next
    tabulated width), over which `prior` spreads the width; `position_ceiling`, `plate_ceiling` and their
    intervals are the M-point ceiling (an upper bound at any M), `rule_plate` the fresh-nuisance rule
    (a lower end of the limit). Plate draws are added until `precision` is met on the ceiling's intervals.
    pair: two positions read jointly (`pair_accuracy`, `pair_truths` observations per plate), as in the
    genie's `ceiling_curves`: from the smallest width until its lower 95 % limit exceeds `pair_until`;
    the plate ceiling is then the least of the singles and the pair.
    """
    widths = [int(w) for w in widths_px]
    if not widths or any(w < 4 for w in widths):
        raise ValueError(f"plate widths must be >= 4 px, got {widths}")
    if not frames or any(t < 1 for t in frames):
        raise ValueError(f"frame counts must be >= 1, got {frames}")
    highs = bin_highs(widths) if width_high_px is None else [float(h) for h in width_high_px]
    if len(highs) != len(widths) or any(h <= w for w, h in zip(widths, highs)):
        raise ValueError(f"width_high_px {highs} must give one bin end above each width of {widths}")
    t0 = time.perf_counter()
    rng, nuisance_rng = np.random.default_rng(seed), np.random.default_rng((seed, NUISANCE_STREAM))
    camera = Camera.of(lens)
    results = []
    n_pos, active = len(model.fmt), pair
    for w, high in zip(widths, highs):
        def draw(n: int) -> np.ndarray:
            return marginal_position_accuracies(camera, w, high, tuple(frames), model, prior, n, noise_draws, rng,
                                                nuisance_rng, active, pair_truths)
        samples = draw(precision.min_plates)
        while not precision.met(_interval(samples[..., 0])[1]) and samples.shape[0] < precision.max_plates:
            samples = np.concatenate([samples, draw(precision.batch)])
        results.append((samples, precision.met(_interval(samples[..., 0])[1])))
        if active is not None and (_interval(samples[..., n_pos, 0])[1][:, 0] > pair_until).all():
            active = None
    seconds = time.perf_counter() - t0
    return [_curve(lens.spec.name, t, n, widths, highs, results, model, prior, noise_draws, precision, seconds, pair)
            for n, t in enumerate(frames)]


def _curve(name: str, frames: int, n: int, widths: list[int], highs: list[float], results: list, model: PlateModel,
           prior: NuisancePrior, noise_draws: int, precision: Precision, seconds: float,
           pair: tuple[int, int] | None) -> CeilingCurve:
    """The CeilingCurve of frame index n from per-width samples (n_plates, F, L, 2)."""
    n_pos = len(model.fmt)
    upper = [s[:, n, :n_pos, 0] for s, _ in results]
    rule = [s[:, n, :n_pos, 1] for s, _ in results]
    position, position_interval = (np.stack(v) for v in zip(*(_interval(s) for s in upper)))
    char, char_interval = (np.stack(v) for v in zip(*(_interval(s.mean(1)) for s in upper)))
    rule_position, rule_position_interval = (np.stack(v) for v in zip(*(_interval(s) for s in rule)))
    pair_ceiling, pair_interval = np.full(len(widths), np.nan), np.full((len(widths), 2), np.nan)
    for k, (s, _) in enumerate(results):
        if s.shape[2] > n_pos:
            pair_ceiling[k], pair_interval[k] = _interval(s[:, n, n_pos, 0])
    # As the genie's: the least block ceiling, its interval the least of the blocks' interval ends.
    plate = np.fmin(position.min(1), pair_ceiling)
    plate_interval = np.stack([np.fmin(position_interval[..., 0].min(1), pair_interval[:, 0]),
                               np.fmin(position_interval[..., 1].min(1), pair_interval[:, 1])], -1)
    rule_interval = np.stack([rule_position_interval[..., 0].min(1), rule_position_interval[..., 1].min(1)], -1)
    return CeilingCurve(
        lens=name, frames=frames, widths_px=np.asarray(widths), char_ceiling=char, char_interval=char_interval,
        position_ceiling=position, position_interval=position_interval, plate_ceiling=plate,
        plate_interval=plate_interval, pair_positions=pair, pair_ceiling=pair_ceiling, pair_interval=pair_interval,
        n_plates=np.asarray([s.shape[0] for s in upper]),
        converged=np.asarray([c for _, c in results]), noise_draws=noise_draws,
        interval_width=precision.interval_width, seconds=seconds, model=model, prior=prior,
        width_high_px=np.asarray(highs), rule_plate=rule_position.min(1), rule_interval=rule_interval)


def convergence(lens: Lens, width_px: int, width_high_px: float | None = None,
                points: tuple[int, ...] = (1, 2, 4, 8, 16, 32, 64), prior: NuisancePrior = DEFAULT_PRIOR,
                model: PlateModel = PlateModel(), seed: int = 0, n_plates: int = 8, noise_draws: int = 2) -> dict:
    """The T = 1 plate ceiling and the fresh-nuisance rule against the number of nuisance points M at one
    width bin, every M on the same plates and noise (one seed), JSON-ready: per M the ceiling and the rule
    with their 95 % intervals and the seconds it took. An exhaustive prior is tabulated at each M of
    `points` as a Sobol set of M points, then (points "all") over its whole support: the exact limit."""
    high = 1.5 * width_px if width_high_px is None else float(width_high_px)
    fixed = Precision(min_plates=n_plates, batch=n_plates, max_plates=n_plates)
    rows = []
    settings: list[tuple[int | str, NuisancePrior]] = [(m, dataclasses.replace(prior, points=m, exhaustive=False))
                                                       for m in points]
    settings += [("all", prior)] if prior.exhaustive else []
    for m, setting in settings:
        t0 = time.perf_counter()
        (curve,) = marginal_ceiling_curves(lens, (width_px,), (1,), model, setting, seed, noise_draws, fixed, [high])
        assert curve.rule_plate is not None and curve.rule_interval is not None  # a marginalised curve has both
        rows.append({"points": m, "plate_ceiling": float(curve.plate_ceiling[0]),
                     "plate_interval": curve.plate_interval[0].tolist(), "rule_plate": float(curve.rule_plate[0]),
                     "rule_interval": curve.rule_interval[0].tolist(), "char_ceiling": float(curve.char_ceiling[0]),
                     "seconds": time.perf_counter() - t0})
    return {"width_px": width_px, "width_high_px": high, "n_plates": n_plates, "noise_draws": noise_draws,
            "seed": seed, "prior": {**_prior_dict(prior), "points": None}, "by_points": rows}


def _prior_dict(prior: NuisancePrior) -> dict:
    return {**dataclasses.asdict(prior), "exposure": list(prior.exposure)}
