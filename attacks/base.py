"""The attacker API: threat models, the fit context, and the Restorer / Reader base classes.

An attacker is one class in one file (see ``attacks/restorers/identity.py`` for the smallest one). It
declares what the adversary is assumed to have (``threat_model``) and which ``FitContext``
fields it needs (``requires``); ``fit`` refuses to start when one of them is missing, so a
mismatch between an attacker and a benchmark configuration fails before any work is done.
The runner, not the attacker, computes metrics, so every attacker is scored the same way.
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

__all__ = [
    "ArtifactStore",
    "Attack",
    "FitContext",
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


@dataclasses.dataclass
class FitContext:
    """Everything an attacker may use to prepare itself; any field may be None.

    Attributes:
        lens: The camera under attack (``LensLike``), or None when the threat model hides it.
        train_pairs: Callable returning a fresh iterable of ``(sensor, sharp)`` batches from the
            TRAIN split, each a tensor (B, 3, H, W) in [0, 1]; callable so it can be re-iterated.
        cache_dir: Directory where the attacker may keep files of its own.
        artifacts: Verified, atomic store for trained weights (``ArtifactStore``); None: cache
            nothing, train every time.
        device: Torch device string the attacker should run on, e.g. "cpu" or "cuda".
        seed: Seed for any randomness in fitting.
        profile: The benchmark profile (smoke / quick / paper) for sizing training, if any.
        extras: Free-form options for attacker-specific inputs.
    """

    lens: LensLike | None = None
    train_pairs: Callable[[], Iterable[tuple[Tensor, Tensor]]] | None = None
    cache_dir: Path | None = None
    artifacts: ArtifactStore | None = None
    device: str = "cpu"
    seed: int = 0
    profile: object | None = None
    extras: dict[str, Any] = dataclasses.field(default_factory=dict)


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

    def fit(self, ctx: FitContext) -> None:
        """Prepare the attacker (measure, train, load weights). The default only checks
        ``requires``; overrides get that check automatically before their body runs."""
        self.check_requirements(ctx)

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
    fit: Callable[[Attack, FitContext], None],
) -> Callable[[Attack, FitContext], None]:
    @functools.wraps(fit)
    def checked_fit(self: Attack, ctx: FitContext) -> None:
        self.check_requirements(ctx)
        fit(self, ctx)

    return checked_fit


class Restorer(Attack):
    """An attacker that rebuilds the sharp scene from sensor images."""

    @abstractmethod
    def restore(self, sensor: Tensor) -> Tensor:
        """Estimate the scene radiance.

        Args:
            sensor: Sensor images, shape (B, 3, H, W), values in [0, 1].

        Returns:
            Restored scenes, shape (B, 3, H, W), values in [0, 1], same device as ``sensor``.
        """


class Reader(Attack):
    """An attacker that reads licence plates from images."""

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
