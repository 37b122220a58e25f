"""The attacker API: threat models, the fit context, and the Restorer / Reader base classes.

An attacker is one class in one file (see ``attacks/restorers/identity.py`` for the smallest one). It
declares what the adversary is assumed to have (``threat_model``) and which ``FitContext``
fields it needs (``requires``); ``fit`` refuses to start when one of them is missing, so a
mismatch between an attacker and a benchmark configuration fails before any work is done.
The runner, not the attacker, computes metrics, so every attacker is scored the same way.

This file is the whole contract: what an attacker may receive is a typed field of ``FitContext``
(its budget an ``AttackBudget``), what its fit says of itself comes back as a ``FitReport``, and a
reader's per-stage timings are its ``stage_seconds``.
"""

from __future__ import annotations

import dataclasses
import functools
from abc import ABC, abstractmethod
from collections.abc import Callable, Iterable, Mapping
from enum import Enum
from pathlib import Path
from typing import Any, ClassVar, Protocol

from torch import Tensor
from torch.nn import Module

from common.plate_render import PLATE_FORMAT

__all__ = [
    "AttackBudget",
    "ArtifactStore",
    "Attack",
    "BUDGET_PROFILES",
    "FitContext",
    "FitCurve",
    "FitReport",
    "LensLike",
    "MissingRequirementError",
    "PlateRead",
    "ReadHints",
    "Reader",
    "Restorer",
    "ThreatModel",
]


class ThreatModel(str, Enum):
    """What the adversary is assumed to have access to."""

    SENSOR_ACCESS = "sensor-access"
    """Only the sensor images of the camera under test."""
    KNOWN_PAIRS = "known-pairs"
    """Sensor images together with the sharp scenes they came from (the TRAIN split)."""
    LENS_ACCESS = "lens-access"
    """The camera itself: its measured PSF and per-channel gain."""
    TRAINING_ADVERSARY = "training-adversary"
    """The adversary network trained jointly with the lens during co-design."""

    @classmethod
    def strongest(cls, *models: ThreatModel | str) -> ThreatModel:
        """The strongest of `models` (values or members): members are declared weakest first, each
        assuming what the one before it has and more (sensor images < with their sharp scenes <
        the camera itself < the co-design's own adversary). A chain of attackers needs what its
        strongest part needs."""
        if not models:
            raise ValueError("ThreatModel.strongest needs at least one threat model")
        order = list(cls)
        return max((cls(m) for m in models), key=order.index)


class LensLike(Protocol):
    """The part of a ``lenses`` lens that attackers may use (structural, so tests can fake it)."""

    spec: Any

    def psf(self) -> Tensor:
        """PSF, shape (3, K, K) for R, G, B; each channel sums to 1; centred at [K//2, K//2]."""
        ...

    def gain(self) -> Tensor:
        """Expected sensor value per unit scene radiance, shape (3,), per channel (QE x exposure)."""
        ...


class ArtifactStore(Protocol):
    """Where an attacker keeps what it trained, addressed by (kind, key); the benchmark's cache
    implements it (``benchmark.store.cache.ArtifactCache``). Writes are atomic and reads verified: a
    missing, truncated or corrupt artifact loads as None (and is reported), so the caller rebuilds it.
    """

    def load(self, kind: str, key: Mapping[str, Any]) -> bytes | None:
        """The bytes stored under (kind, key), or None when absent or corrupt."""
        ...

    def save(self, kind: str, key: Mapping[str, Any], data: bytes) -> Path:
        """Store ``data`` under (kind, key); returns where it went."""
        ...


BUDGET_PROFILES = ("tiny", "smoke", "quick", "paper")
"""The budgets an attacker may be given, smallest first: ``tiny`` (a contract test: any fit in well under a
second) and the benchmark's three profiles."""


@dataclasses.dataclass(frozen=True)
class AttackBudget:
    """How much an attacker may spend preparing itself: the run's profile and the size of a trained restorer.

    Attributes:
        profile: One of ``BUDGET_PROFILES``; a trained attacker sizes what the fields below do not say
            by it (the learned reader's fine-tune, say).
        restorer_steps: Optimiser steps of a trained restorer.
        nafnet_width, nafnet_enc_blocks, nafnet_middle_blocks, nafnet_dec_blocks: A trained NAFNet's
            architecture (channels; blocks per encoder level, in the middle, per decoder level).
        crop_px: Side of the square training crops, in pixels (even: keeps the Bayer phase).
        batch_size: Training crops per step.
        max_train_images: How many training images to draw from the TRAIN split.
    """

    profile: str = "tiny"
    restorer_steps: int = 2
    nafnet_width: int = 4
    nafnet_enc_blocks: tuple[int, ...] = (1,)
    nafnet_middle_blocks: int = 1
    nafnet_dec_blocks: tuple[int, ...] = (1,)
    crop_px: int = 32
    batch_size: int = 2
    max_train_images: int = 4

    def __post_init__(self) -> None:
        if self.profile not in BUDGET_PROFILES:
            raise ValueError(f"AttackBudget.profile {self.profile!r} is not a budget; valid: {list(BUDGET_PROFILES)}")
        counts = {"restorer_steps": self.restorer_steps, "nafnet_width": self.nafnet_width,
                  "nafnet_middle_blocks": self.nafnet_middle_blocks, "crop_px": self.crop_px,
                  "batch_size": self.batch_size, "max_train_images": self.max_train_images}
        for name, value in counts.items():
            if not isinstance(value, int) or isinstance(value, bool) or value < 1:
                raise ValueError(f"AttackBudget.{name} must be an int >= 1, got {value!r}")
        if self.crop_px % 2:
            raise ValueError(f"AttackBudget.crop_px must be even (it keeps the Bayer phase), got {self.crop_px}")
        for name in ("nafnet_enc_blocks", "nafnet_dec_blocks"):
            blocks = getattr(self, name)
            if not blocks or any(not isinstance(b, int) or b < 1 for b in blocks):
                raise ValueError(f"AttackBudget.{name} must be a non-empty tuple of ints >= 1, got {blocks!r}")


@dataclasses.dataclass
class FitContext:
    """Everything an attacker may use to prepare itself, as typed fields; an attacker names the
    optional ones it cannot do without in ``requires``.

    Attributes:
        lens: The camera under attack (``LensLike``), or None when the threat model hides it (and for
            the sharp scenes themselves).
        train_pairs: Callable returning a fresh iterable of ``(sensor, sharp)`` batches from the
            TRAIN split, each a tensor (B, 3, H, W) in [0, 1]; callable so it can be re-iterated.
        cache_dir: Directory where the attacker may keep files of its own.
        artifacts: Verified, atomic store for trained weights (``ArtifactStore``); None: cache
            nothing, train every time.
        device: Torch device string the attacker should run on, e.g. "cpu" or "cuda".
        seed: Seed for any randomness in fitting.
        budget: How much fitting may cost (``AttackBudget``); the default is the ``tiny`` budget.
        segmenter: A segmentation network as a callable, images (B, 3, H, W) in [0, 1] -> Cityscapes
            train ids (B, H, W): the lens's own utility network, for attackers that find vehicles
            with it (``lpdr``); None when the run has none.
        plate_format: The format of the scenes' plate strings, one character per slot ("L" a letter,
            "D" a digit; ``common.plate_render``).
        adversary: The deblurring network co-designed with the lens (sensor (B, 3, H, W) -> scene
            estimate, a ``torch.nn.Module``), under the training-adversary threat model; None for a
            lens designed without one.
    """

    lens: LensLike | None = None
    train_pairs: Callable[[], Iterable[tuple[Tensor, Tensor]]] | None = None
    cache_dir: Path | None = None
    artifacts: ArtifactStore | None = None
    device: str = "cpu"
    seed: int = 0
    budget: AttackBudget = dataclasses.field(default_factory=AttackBudget)
    segmenter: Callable[[Tensor], Tensor] | None = None
    plate_format: str = PLATE_FORMAT
    adversary: Module | None = None


@dataclasses.dataclass(frozen=True)
class FitCurve:
    """A trained attacker's held-out score against its training step.

    Attributes:
        steps: Optimiser steps at which it was evaluated, increasing.
        scores: The held-out score at each step (higher is better; ``metric`` says what it is).
        metric: What ``scores`` measure, e.g. "held-out plate accuracy".
        stopped: Why the fit ended: "flattened" (the score stopped improving) or "budget" (it ran out of steps).
        kept_step: The step whose weights the fit kept.
    """

    steps: tuple[int, ...]
    scores: tuple[float, ...]
    metric: str
    stopped: str
    kept_step: int

    def __post_init__(self) -> None:
        if len(self.steps) != len(self.scores):
            raise ValueError(f"FitCurve: {len(self.steps)} steps but {len(self.scores)} scores")
        if self.stopped not in ("flattened", "budget"):
            raise ValueError(f"FitCurve.stopped must be 'flattened' or 'budget', got {self.stopped!r}")


@dataclasses.dataclass(frozen=True)
class FitReport:
    """What ``Attack.fit`` says of itself; the runner writes it into the attacker's rows.

    Attributes:
        curve: The held-out curve of a trained attacker; None for one that trains nothing (or keeps none).
        still_rising: Whether the fit stopped while its held-out score was still improving (a privacy
            figure from it then overstates privacy); None when the attacker does not train.
        stage_seconds: Wall seconds per named stage of the fit (e.g. {"pretrain": 12.0, "fine-tune": 80.0}).
    """

    curve: FitCurve | None = None
    still_rising: bool | None = None
    stage_seconds: Mapping[str, float] = dataclasses.field(default_factory=dict)


_CONTEXT_FIELDS = frozenset(f.name for f in dataclasses.fields(FitContext))


class MissingRequirementError(ValueError):
    """An attacker's ``fit`` got a ``FitContext`` lacking a field the attacker ``requires``."""


@dataclasses.dataclass(frozen=True)
class PlateRead:
    """One licence plate read from one image.

    Attributes:
        text: The plate string as read (upper-case letters and digits by convention).
        box_xyxy: Plate box (x0, y0, x1, y1) in pixels of the image that was read.
        score: Reader confidence in [0, 1].
    """

    text: str
    box_xyxy: tuple[float, float, float, float]
    score: float


@dataclasses.dataclass(frozen=True)
class ReadHints:
    """What the runner may hand a reader besides the images.

    Attributes:
        vehicle_boxes: Ground-truth vehicle boxes (x0, y0, x1, y1) per image, for an attacker's
            upper bound (an ``oracle`` vehicle stage); None when not offered.
        segment: A segmentation network as a callable, images (B, 3, H, W) in [0, 1] ->
            Cityscapes train ids (B, H, W): the lens's own utility network for sensor images, a
            clean-trained one for sharp or restored images; None when there is none.
        plate_boxes: Ground-truth plate boxes (x0, y0, x1, y1) per image, in pixels, for readers
            that are told where the plates are (``ideal-observer``); None when not offered.
    """

    vehicle_boxes: list[list[tuple[float, float, float, float]]] | None = None
    segment: Callable[[Tensor], Tensor] | None = None
    plate_boxes: list[list[tuple[float, float, float, float]]] | None = None


_HINT_FIELDS = frozenset(f.name for f in dataclasses.fields(ReadHints))


def box_iou(a: tuple[float, ...], b: tuple[float, ...]) -> float:
    """Intersection over union of two (x0, y0, x1, y1) boxes; 0 when the union is empty."""
    ix = max(0.0, min(a[2], b[2]) - max(a[0], b[0]))
    iy = max(0.0, min(a[3], b[3]) - max(a[1], b[1]))
    inter = ix * iy
    union = (a[2] - a[0]) * (a[3] - a[1]) + (b[2] - b[0]) * (b[3] - b[1]) - inter
    return inter / union if union > 0 else 0.0


class Attack(ABC):
    """Base of every attacker.

    Subclasses set the class attributes ``name`` (the registered name), ``threat_model`` and
    ``requires`` (names of ``FitContext`` fields that must not be None), and subclass
    ``Restorer`` or ``Reader``. Constructor keyword arguments are the attacker's options
    (``attacks.load(name, **options)``).
    """

    name: ClassVar[str]
    threat_model: ClassVar[ThreatModel]
    requires: ClassVar[frozenset[str]] = frozenset()
    # False: the attacker runs only when named (e.g. a much slower variant of a default one).
    run_by_default: ClassVar[bool] = True
    # True: a reference row (kind "reference"), not an attack: it shows a condition (e.g. the
    # uncorrected sensor image) and never counts as a lens's worst case.
    reference: ClassVar[bool] = False
    # True: the attacker fits weights to data (training pairs, scenes, plates, a lens family). The runner
    # records it in its rows (note ``learns``), and a learning attacker that loses to one that learns
    # nothing, of an equal or weaker threat model, is flagged as under-fitted.
    learns: ClassVar[bool] = False

    def __init_subclass__(cls, **kwargs: Any) -> None:
        super().__init_subclass__(**kwargs)
        unknown = set(cls.requires) - _CONTEXT_FIELDS
        if unknown:
            raise TypeError(
                f"{cls.__qualname__}.requires names {sorted(unknown)}, which are not FitContext "
                f"fields; valid: {sorted(_CONTEXT_FIELDS)}"
            )
        # Wrap an overriding ``fit`` so the requirement check runs even when a plugin author
        # forgets to call super().fit(): missing inputs must fail before any training starts.
        if "fit" in cls.__dict__:
            cls.fit = _checking_requirements(cls.__dict__["fit"])  # type: ignore[method-assign, assignment]

    def check_requirements(self, ctx: FitContext) -> None:
        """Raise ``MissingRequirementError`` naming this attacker and every required field of
        ``ctx`` that is None."""
        missing = sorted(f for f in self.requires if getattr(ctx, f) is None)
        if missing:
            raise MissingRequirementError(
                f"attacker {self.name!r} ({self.threat_model.value}) requires FitContext "
                f"field(s) {missing}, but they are None"
            )

    def skip_reason(self, ctx: FitContext) -> str | None:
        """Why this attacker does not apply to this context (e.g. no co-design adversary for a
        fixed lens), or None when it applies. The runner skips it with this message."""
        return None

    def fit(self, ctx: FitContext) -> FitReport:
        """Prepare the attacker (measure, train, load weights) and say how it went (``FitReport``).

        The default only checks ``requires``. Overrides get that check automatically before their body
        runs, and an override that returns nothing reports an empty ``FitReport()``."""
        self.check_requirements(ctx)
        return FitReport()

    def describe(self) -> dict[str, Any]:
        """JSON-serializable configuration of this attacker, for caching and provenance.
        Subclasses with options extend it: ``{**super().describe(), "option": value}``."""
        cls = type(self)
        return {
            "name": self.name,
            "threat_model": self.threat_model.value,
            "class": f"{cls.__module__}:{cls.__qualname__}",
        }


def _checking_requirements(
    fit: Callable[[Attack, FitContext], FitReport | None],
) -> Callable[[Attack, FitContext], FitReport]:
    @functools.wraps(fit)
    def checked_fit(self: Attack, ctx: FitContext) -> FitReport:
        self.check_requirements(ctx)
        report = fit(self, ctx)
        if report is None:
            return FitReport()
        if not isinstance(report, FitReport):
            raise TypeError(f"{type(self).__qualname__}.fit returned {type(report).__name__}; "
                            "it returns an attacks.FitReport (or None for an empty one)")
        return report

    return checked_fit


class Restorer(Attack):
    """An attacker that rebuilds the sharp scene from sensor images."""

    def restoration_key(self) -> str | None:
        """After ``fit``: a fingerprint of everything its ``restore`` depends on, or None (the default: no
        claim). Two restorers of one run with equal keys return the same images for every input, so the
        runner restores once and scores both from it (a fine-tune that kept its start is its start)."""
        return None

    @abstractmethod
    def restore(self, sensor: Tensor) -> Tensor:
        """Estimate the scene radiance.

        Args:
            sensor: Sensor images, shape (B, 3, H, W), values in [0, 1].

        Returns:
            Restored scenes, shape (B, 3, H, W), values in [0, 1], same device as ``sensor``.
        """


class Reader(Attack):
    """An attacker that reads licence plates from images.

    ``hints`` names the ``ReadHints`` fields the reader reads (``vehicle_boxes``, ``segment``,
    ``plate_boxes``); the runner hands it those and leaves the others None, so a reader is told the
    ground-truth boxes only when it declares it (an oracle stage), and its settings say so.

    ``stage_seconds`` holds the cumulative wall seconds a reader spent in each named stage of its reads
    (``lpdr``: vehicles, plates, ocr); the runner reports its growth over a chain as
    ``<stage>_s_per_image``. A reader without stages leaves it empty.
    """

    hints: ClassVar[frozenset[str]] = frozenset()

    def __init_subclass__(cls, **kwargs: Any) -> None:
        super().__init_subclass__(**kwargs)
        unknown = set(cls.hints) - _HINT_FIELDS
        if unknown:
            raise TypeError(f"{cls.__qualname__}.hints names {sorted(unknown)}, which are not ReadHints fields; "
                            f"valid: {sorted(_HINT_FIELDS)}")

    def describe(self) -> dict[str, Any]:
        """The base description and the hints the reader is given (sorted)."""
        return {**super().describe(), "hints": sorted(self.hints)}

    @property
    def stage_seconds(self) -> dict[str, float]:
        return self.__dict__.setdefault("_stage_seconds", {})

    @stage_seconds.setter
    def stage_seconds(self, seconds: dict[str, float]) -> None:
        self.__dict__["_stage_seconds"] = seconds

    @abstractmethod
    def read(self, images: Tensor, hints: ReadHints | None = None) -> list[list[PlateRead]]:
        """Read every plate in every image.

        Args:
            images: Images, shape (B, 3, H, W), values in [0, 1] (sensor or restored).
            hints: Optional side information for the stages that use it (``ReadHints``).

        Returns:
            One list of ``PlateRead`` per image (empty when nothing was read), length B.
        """

    def read_batches(self, batches: Iterable[tuple[Tensor, ReadHints | None]]) -> list[list[list[PlateRead]]]:
        """``read`` of each (images, hints) batch, in order: one list of reads per image of each batch.

        A reader may override it to share work across batches (``lpdr`` recognises the plate crops
        of every batch together); the reads must be those ``read`` gives batch by batch.
        """
        return [self.read(images, hints) for images, hints in batches]
