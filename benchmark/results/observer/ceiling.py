"""The ideal observer's ceiling on reading a plate through a lens, per plate width and frame count.

The observer knows everything but the characters: the format, the font and renderer (the scenes'
own `render_plate`), the plate's size, position, background, exposure and surround (`PlateModel`),
the lens's PSF per channel, the sensor's electrons per unit radiance and read noise. Characters are
uniform over the format's alphabets. It sees the raw electrons of T frames (`lenses.raw_likelihood`:
the sensor image is a function of them, so its accuracy bounds every attacker of sensor images).

Per-character ceiling. A genie also reveals every other character of the plate. For position i the
observer then faces an |A_i|-ary test between fully known mean images mu_a (the whole plate rendered
with character a at i, blurred, mosaicked), and the maximum-likelihood rule (the MAP rule: the prior
is uniform) is the optimal decision, with accuracy

    c_i = E_y[max_a P(a | y)]       (y drawn from the uniform mixture over a).

Extra knowledge never hurts an optimal observer, so c_i bounds the probability that ANY attacker
(without the genie) reads character i correctly. The Monte-Carlo estimate averages max_a P(a | y)
rather than the 0/1 correctness of the ML decision: the same mean (it is its conditional
expectation given y), a smaller variance.

Whole-plate ceiling. Reading the plate exactly implies reading any block S of positions correctly,
so P(exact) <= P(block S correct) <= c_S, the accuracy of the optimal joint decision on S with a
genie revealing the other characters (the same argument as for one character). Hence
P(exact) <= min over blocks S of c_S, proven for any set of blocks; `plate_ceiling` is the least of
the seven single-character c_i and of the pair c_{01} (the first two letters, 676 hypotheses; it
is also <= c_0 and c_1, since a right pair has both right). The pair matters where the characters
are near chance: a single letter cannot be certified below 1/26 = 3.8 % nor a digit below 10 %,
a pair of letters down to 1/676. The product prod_i c_i is NOT an upper bound in general: the
events "character i correct" of one attacker are not independent (a sharp frame makes all of them
likely together), and P(A and B) can exceed P(A) P(B); it is not used.

Monte Carlo. Plates are drawn uniformly from the format; for each plate, each position and each
hypothesis a as the truth, `noise_draws` observations. The per-plate averages are i.i.d. with mean
c_i; the 95 % interval is mean +- 1.96 standard errors across plate draws (it holds the noise and
plate variation together). Plate draws are added in batches until every position's interval is
narrower than `interval_width` (default 1 point) or `max_plates` is reached; `converged` says which.

Left out, each in the observer's favour, so the ceiling stays an upper bound: the scenes' texture
shading of the plate (unknown to a real attacker), haze (lowers the plate's contrast), the ADC and
clip (data processing). The appearance is the most legible one the synthetic scenes draw (white
plate, no EU band, the highest exposure): more light at the same contrast raises the SNR.
"""

from __future__ import annotations

import dataclasses
import itertools
import math
import time
from dataclasses import dataclass, field

import numpy as np
import torch

from benchmark.results.observer.nuisance import NuisancePrior
from common.plate_render import PLATE_FORMAT, PLATE_SIZE_M, format_alphabets, random_plate_text, render_plate
from lenses.depth import plate_distance_m
from lenses.lens import Lens
from lenses.raw_likelihood import draw_statistics, log_likelihoods, raw_mean_electrons

Z95 = 1.959963984540054


@dataclass(frozen=True)
class PlateModel:
    """Everything about a plate that the observer is told, besides its characters.

    background_rgb: plate colour in 8-bit values (scene radiance = value / 255 * exposure);
    exposure: the synthetic scenes draw 0.85-1.05, 1.05 the most favourable to the observer;
    surround_radiance: the known uniform radiance around the plate (default: the plate's own dark
    border colour, a dark car body); aspect: plate width / height (EU plate).
    """

    fmt: str = PLATE_FORMAT
    background_rgb: tuple[int, int, int] = (236, 236, 228)
    exposure: float = 1.05
    eu_band: bool = False
    surround_radiance: float = 20 / 255
    aspect: float = PLATE_SIZE_M[0] / PLATE_SIZE_M[1]

    def height_px(self, width_px: int) -> int:
        return max(2, round(width_px / self.aspect))


@dataclass(frozen=True)
class Camera:
    """The observer's knowledge of the lens: PSF (3, K, K), e- per unit radiance (3,), read noise in e-."""

    psf: torch.Tensor
    electrons_per_unit: torch.Tensor
    read_noise_e: float

    @classmethod
    def of(cls, lens: torch.nn.Module) -> Camera:
        with torch.no_grad():
            return cls(lens.psf().detach().to(torch.float64).cpu(),
                       lens.sensor.electrons_per_unit().detach().to(torch.float64).cpu(),
                       float(lens.spec.sensor.read_noise_e))


@dataclass
class CeilingCurve:
    """Ceilings per plate width (index n) and character position (index i), fractions in [0, 1].

    char_ceiling (n,): mean over positions of c_i, the genie-aided per-character accuracy;
    position_ceiling (n, L) and position_interval (n, L, 2): c_i and its 95 % interval;
    plate_ceiling (n,) = min(min_i c_i, c_pair), the proven bound on P(exact plate read), plate_interval (n, 2);
    pair_ceiling (n,), pair_interval (n, 2): c_pair of `pair_positions` read jointly (NaN where not computed);
    n_plates (n,): plate draws used; converged (n,): every interval narrower than interval_width;
    object_distance_m (n,) when each width used the PSF at its own distance, else None.
    prior: None for the genie (every nuisance known); else the `NuisancePrior` the marginalised ceiling
    (`marginal.py`) averaged over, width w_k standing for the bin [w_k, width_high_px[k]), and rule_plate
    (n,), rule_interval (n, 2): its fresh-nuisance rule, a lower end of the ceiling's M -> infinity limit.
    """

    lens: str
    frames: int
    widths_px: np.ndarray
    char_ceiling: np.ndarray
    char_interval: np.ndarray
    position_ceiling: np.ndarray
    position_interval: np.ndarray
    plate_ceiling: np.ndarray
    plate_interval: np.ndarray
    n_plates: np.ndarray
    converged: np.ndarray
    noise_draws: int
    interval_width: float
    seconds: float
    object_distance_m: np.ndarray | None = None
    model: PlateModel = field(default_factory=PlateModel)
    pair_positions: tuple[int, int] | None = None
    pair_ceiling: np.ndarray | None = None
    pair_interval: np.ndarray | None = None
    prior: NuisancePrior | None = None
    width_high_px: np.ndarray | None = None
    rule_plate: np.ndarray | None = None
    rule_interval: np.ndarray | None = None

    @property
    def kind(self) -> str:
        """"genie" (every nuisance known: the proven bound) or "marginal" (the tighter ceiling)."""
        return "genie" if self.prior is None else "marginal"

    def to_dict(self) -> dict:
        """JSON-ready dict (lists of floats)."""
        out = {}
        for f in dataclasses.fields(self):
            value = getattr(self, f.name)
            if isinstance(value, np.ndarray):
                value = np.where(np.isnan(value), None, value).tolist() if value.dtype.kind == "f" else value.tolist()
            elif isinstance(value, (PlateModel, NuisancePrior)):
                value = dataclasses.asdict(value)
            out[f.name] = value
        return out

    @classmethod
    def from_dict(cls, d: dict) -> CeilingCurve:
        """The curve of a `to_dict` dict (None in float arrays back to NaN); errors name a missing field."""
        missing = [f.name for f in dataclasses.fields(cls) if f.name not in d and f.default is dataclasses.MISSING
                   and f.default_factory is dataclasses.MISSING]
        if missing:
            raise ValueError(f"ceiling curve dict lacks {missing}; it must come from CeilingCurve.to_dict")
        scalars = {"lens", "frames", "noise_draws", "interval_width", "seconds"}
        dtypes = {"widths_px": int, "n_plates": int, "converged": bool}  # the other arrays: float, None -> NaN
        kwargs: dict = {}
        for f in dataclasses.fields(cls):
            if f.name not in d:
                continue
            value = d[f.name]
            if f.name == "model":
                value = PlateModel(**{k: tuple(v) if isinstance(v, list) else v for k, v in value.items()})
            elif f.name == "prior":
                value = None if value is None else NuisancePrior(**{k: tuple(v) if isinstance(v, list) else v
                                                                    for k, v in value.items()})
            elif f.name == "pair_positions":
                value = None if value is None else tuple(value)
            elif f.name not in scalars and value is not None:
                value = np.asarray(value, dtype=dtypes.get(f.name, float))
            kwargs[f.name] = value
        return cls(**kwargs)


def hypothesis_means(camera: Camera, texts: list[str], width_px: int, model: PlateModel) -> torch.Tensor:
    """Mean raw electrons (A, P) of the plate rendered with each text, over the plate +- the PSF radius."""
    size = (width_px, model.height_px(width_px))
    plates = np.stack([np.asarray(render_plate(t, size, model.background_rgb, model.eu_band)) for t in texts])
    radiance = torch.from_numpy(plates.astype(np.float64) / 255 * model.exposure).permute(0, 3, 1, 2)
    means = raw_mean_electrons(radiance, model.surround_radiance, camera.psf, camera.electrons_per_unit)
    return means.reshape(len(texts), -1)


def ideal_accuracy(means_e: torch.Tensor, read_noise_e: float, frames: int, noise_draws: int,
                   rng: np.random.Generator) -> tuple[float, float]:
    """(E max posterior, ML hit rate) of the |A|-ary test between known means_e (A, P), uniform prior.

    Each hypothesis is the truth for `noise_draws` observations of T = `frames` frames. Both numbers
    estimate the same accuracy; the first has the smaller variance.
    """
    varying = (means_e.max(0).values - means_e.min(0).values) > 0
    means = means_e[:, varying]
    n_hyp = means.shape[0]
    if means.shape[1] == 0:  # identical hypotheses: the posterior is uniform
        return 1.0 / n_hyp, 1.0 / n_hyp
    s1, s2 = draw_statistics(means.repeat_interleave(noise_draws, dim=0), read_noise_e, frames, rng)
    loglik = log_likelihoods(s1, s2, frames, means, read_noise_e)
    posterior = torch.softmax(loglik, dim=-1)
    truth = torch.arange(n_hyp).repeat_interleave(noise_draws)
    best = loglik.max(dim=-1, keepdim=True).values
    ties = (loglik == best)
    hits = ties[torch.arange(len(truth)), truth].double() / ties.sum(-1)
    return float(posterior.max(-1).values.mean()), float(hits.mean())


def block_accuracy(camera: Camera, text: str, block: tuple[int, ...], width_px: int, frames: tuple[int, ...],
                   model: PlateModel, noise_draws: int, rng: np.random.Generator) -> np.ndarray:
    """(len(frames),) estimates of the genie-aided accuracy of reading the positions `block` of
    plate `text` jointly (every other character revealed): one draw per frame count."""
    alphabets = format_alphabets(model.fmt)
    texts = []
    for values in itertools.product(*(alphabets[i] for i in block)):
        chars = list(text)
        for i, v in zip(block, values):
            chars[i] = v
        texts.append("".join(chars))
    means = hypothesis_means(camera, texts, width_px, model)
    return np.array([ideal_accuracy(means, camera.read_noise_e, t, noise_draws, rng)[0] for t in frames])


def position_accuracies(camera: Camera, width_px: int, frames: tuple[int, ...], model: PlateModel, n_plates: int,
                        noise_draws: int, rng: np.random.Generator,
                        pair: tuple[int, int] | None = None) -> np.ndarray:
    """(n_plates, len(frames), L [+ 1]) per-plate estimates of c_i (E max posterior) at one width,
    and of the pair ceiling c_pair as a last column when `pair` is given.

    The frame counts share the plate draws and their rendered hypotheses (the costly part)."""
    blocks = [(i,) for i in range(len(model.fmt))] + ([tuple(pair)] if pair is not None else [])
    out = np.empty((n_plates, len(frames), len(blocks)))
    for j in range(n_plates):
        text = random_plate_text(rng, model.fmt)
        for b, block in enumerate(blocks):
            # One observation per hypothesis suffices for a pair: it has |A|^2 of them.
            draws = noise_draws if len(block) == 1 else 1
            out[j, :, b] = block_accuracy(camera, text, block, width_px, frames, model, draws, rng)
    return out


def _interval(samples: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Mean over axis 0 and its 95 % normal interval (..., 2), clipped to [0, 1]."""
    mean = samples.mean(0)
    half = Z95 * samples.std(0, ddof=1) / math.sqrt(samples.shape[0])
    return mean, np.clip(np.stack([mean - half, mean + half], -1), 0.0, 1.0)


@dataclass(frozen=True)
class Precision:
    """When to stop drawing plates: every interval that reaches below `precise_below` must be narrower
    than `interval_width` (where W_5% is decided), every other one narrower than `coarse_width`."""

    interval_width: float = 0.01
    precise_below: float = 0.10
    coarse_width: float = 0.05
    min_plates: int = 8
    batch: int = 8
    max_plates: int = 400

    def met(self, interval: np.ndarray) -> bool:
        width = interval[..., 1] - interval[..., 0]
        needed = np.where(interval[..., 0] < self.precise_below, self.interval_width, self.coarse_width)
        return bool((width < needed).all())


def width_ceiling(camera: Camera, width_px: int, frames: tuple[int, ...], model: PlateModel,
                  rng: np.random.Generator, noise_draws: int = 2, precision: Precision = Precision(),
                  pair: tuple[int, int] | None = None) -> tuple[np.ndarray, bool]:
    """Per-plate estimates (n_plates, len(frames), L [+ 1]) of every c_i (and c_pair) at one width, and
    whether `precision` was met (plate draws are added until it is, or up to its max_plates)."""
    samples = position_accuracies(camera, width_px, frames, model, precision.min_plates, noise_draws, rng, pair)
    while True:
        done = precision.met(_interval(samples)[1])
        if done or samples.shape[0] >= precision.max_plates:
            return samples, done
        more = position_accuracies(camera, width_px, frames, model, precision.batch, noise_draws, rng, pair)
        samples = np.concatenate([samples, more])


def lens_at_distance(lens: torch.nn.Module, object_distance_m: float) -> torch.nn.Module:
    """The same lens (current coefficients) imaging an object plane at `object_distance_m`."""
    spec = lens.current_spec()
    return Lens(dataclasses.replace(spec, optics=dataclasses.replace(spec.optics, object_distance_m=object_distance_m)))


def ceiling_curves(lens: torch.nn.Module, widths_px: tuple[int, ...] | list[int], frames: tuple[int, ...] = (1,),
                   model: PlateModel = PlateModel(), seed: int = 0, at_own_distance: bool = False,
                   noise_draws: int = 2, precision: Precision = Precision(), pair: tuple[int, int] | None = (0, 1),
                   pair_until: float = 0.10) -> list[CeilingCurve]:
    """One `CeilingCurve` per frame count, through `lens`, for each plate width in px (module docstring).

    pair: two positions read jointly with the rest revealed (a tighter plate bound, see the module
    docstring), computed from the smallest width up to the first width where its lower 95 % limit
    exceeds `pair_until` for every frame count (beyond, the plate bound is the single-character
    minimum, valid and looser; W_5% is decided below). None: singles only.

    at_own_distance: for each width, the PSF of an object plane at the distance where the format's
    plate (PLATE_SIZE_M wide) is that many pixels wide (`lenses.depth.plate_distance_m`); else the
    lens's own PSF (its spec's object distance) at every width. The frame counts share plate draws.
    """
    widths = [int(w) for w in widths_px]
    if not widths or any(w < 4 for w in widths):
        raise ValueError(f"plate widths must be >= 4 px, got {widths}")
    if not frames or any(t < 1 for t in frames):
        raise ValueError(f"frame counts must be >= 1, got {frames}")
    t0 = time.perf_counter()
    rng = np.random.default_rng(seed)
    results, distances = [], []
    camera = Camera.of(lens)
    n_pos = len(model.fmt)
    active = pair
    for w in widths:
        if at_own_distance:
            distances.append(plate_distance_m(w, PLATE_SIZE_M[0], lens.spec))
            camera = Camera.of(lens_at_distance(lens, distances[-1]))
        results.append(width_ceiling(camera, w, tuple(frames), model, rng, noise_draws, precision, active))
        if active is not None and (_interval(results[-1][0][..., n_pos])[1][:, 0] > pair_until).all():
            active = None
    seconds = time.perf_counter() - t0
    curves = []
    for n, t in enumerate(frames):
        per_width = [samples[:, n, :n_pos] for samples, _ in results]
        position, position_interval = (np.stack(v) for v in zip(*(_interval(s) for s in per_width)))
        char, char_interval = (np.stack(v) for v in zip(*(_interval(s.mean(1)) for s in per_width)))
        pair_ceiling, pair_interval = np.full(len(widths), np.nan), np.full((len(widths), 2), np.nan)
        for k, (samples, _) in enumerate(results):
            if samples.shape[-1] > n_pos:
                pair_ceiling[k], pair_interval[k] = _interval(samples[:, n, n_pos])
        # The plate bound is the least of the block ceilings; the least of their interval ends covers
        # it whenever every interval covers its own ceiling.
        with np.errstate(invalid="ignore"):
            plate = np.fmin(position.min(1), pair_ceiling)
            plate_interval = np.stack([np.fmin(position_interval[..., 0].min(1), pair_interval[:, 0]),
                                       np.fmin(position_interval[..., 1].min(1), pair_interval[:, 1])], -1)
        curves.append(CeilingCurve(
            lens=lens.spec.name, frames=t, widths_px=np.asarray(widths), char_ceiling=char,
            char_interval=char_interval, position_ceiling=position, position_interval=position_interval,
            plate_ceiling=plate, plate_interval=plate_interval, pair_positions=pair,
            pair_ceiling=pair_ceiling, pair_interval=pair_interval,
            n_plates=np.asarray([s.shape[0] for s in per_width]), converged=np.asarray([c for _, c in results]),
            noise_draws=noise_draws, interval_width=precision.interval_width, seconds=seconds,
            object_distance_m=np.asarray(distances) if at_own_distance else None, model=model))
    return curves


def ceiling_curve(lens: torch.nn.Module, widths_px: tuple[int, ...] | list[int], frames: int = 1,
                  **options: object) -> CeilingCurve:
    """The `CeilingCurve` of one frame count T = `frames`; options as for `ceiling_curves`."""
    return ceiling_curves(lens, widths_px, (frames,), **options)[0]  # type: ignore[arg-type]


def certified_width(curve: CeilingCurve, eps: float = 0.05, per_character: bool = False) -> int:
    """W_eps: the largest tabulated width whose ceiling (plate by default) is <= eps at it and every
    smaller tabulated width; 0 when the smallest width is already above eps."""
    values = curve.char_ceiling if per_character else curve.plate_ceiling
    certified = 0
    for w, c in zip(curve.widths_px, values):
        if c > eps:
            break
        certified = int(w)
    return certified
