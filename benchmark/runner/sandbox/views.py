"""What crosses into an attacker's process in place of the runner's own objects.

The lens becomes a ``LensView`` (its spec with the current coefficients, its PSF and gain as
tensors: the ``attacks.LensLike`` contract, nothing of the runner's simulation), and every
callable of the fit context or the read hints (training pairs, segmenters) becomes a ``RemoteRef``
that the attacker's process turns into a call back to the runner (``worker``): the runner computes
it and hands back only its result.
"""

from __future__ import annotations

import dataclasses
from typing import Any

import torch


@dataclasses.dataclass(frozen=True)
class RemoteRef:
    """A callable that stays in the runner; `target` names it ("train_pairs", "segmenter", "segment")."""

    target: str


@dataclasses.dataclass
class LensView:
    """The lens an isolated attacker sees (``attacks.LensLike``): spec, PSF (3, K, K), gain (3,)."""

    spec: Any
    psf_: torch.Tensor
    gain_: torch.Tensor

    @classmethod
    def of(cls, lens: Any) -> LensView:
        """The view of a lens (a ``lenses.Lens`` or any ``LensLike``), detached from its graph."""
        spec = lens.current_spec() if hasattr(lens, "current_spec") else lens.spec
        with torch.no_grad():
            return cls(spec, lens.psf().detach().clone(), lens.gain().detach().clone())

    def psf(self) -> torch.Tensor:
        """PSF, (3, K, K), each channel summing to 1."""
        return self.psf_.clone()

    def gain(self) -> torch.Tensor:
        """Expected sensor value per unit radiance, (3,)."""
        return self.gain_.clone()

    def current_spec(self) -> Any:
        """The lens's spec with its current coefficients (as ``lenses.Lens.current_spec``)."""
        return self.spec
