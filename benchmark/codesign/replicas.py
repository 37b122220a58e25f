"""How one co-design step is spread over processes: the single-process case of the interface.

The loop (`benchmark.codesign.trainer`) and the balancing methods are written against this
interface so that `benchmark.codesign.distributed.DataParallel` can split each batch over ranks.
"""

from __future__ import annotations

from collections.abc import Callable
from typing import Any

import torch

from lenses.lens import Lens


class SingleProcess:
    """How one training step is spread over replicas: here, one process holds the whole batch.

    Every method here is an exact identity, so single-process training computes bit for bit what
    it did before data parallelism existed.
    """

    world = 1
    is_writer = True         # this process writes checkpoints and publishes the artifacts
    reduction = "mean"       # loss reduction over the local rows (see `scale`)

    def rows(self, batch_size: int) -> slice:
        """The rows of the global batch this process trains on."""
        return slice(0, batch_size)

    def scale(self, count: torch.Tensor | int) -> float | torch.Tensor:
        """Factor turning the `reduction` of a loss over local rows into this process's estimate of
        the global-batch mean, given `count` elements in the global batch (1 here: mean is the mean)."""
        return 1.0

    def sense(self, lens: Lens, x: torch.Tensor, rows: slice, generator: torch.Generator) -> torch.Tensor:
        """Sensor images (b,3,h,w) of rows `rows` of the global scene batch x (B,3,h,w)."""
        return lens(x, generator=generator)

    def fitting(self, module: torch.nn.Module) -> torch.nn.Module:
        """The module to call for the networks' own training step (gradients reach their optimiser)."""
        return module

    def mean(self, t: torch.Tensor) -> torch.Tensor:
        """The mean over replicas of a per-replica estimate (no gradient)."""
        return t

    def item(self, t: torch.Tensor) -> float:
        return t.item()

    def gradient_penalty(self, g: torch.Tensor, reference: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor]:
        """(penalty value, term whose gradient, averaged over replicas, is the penalty's) for this
        replica's estimate g of dL_deb/dtheta and a detached reference norm (the same on every
        replica): here the penalty (||g|| / reference - 1)^2 itself."""
        penalty = (g.norm() / reference - 1.0) ** 2
        return penalty.detach(), penalty

    def writer_first(self, fn: Callable[[], Any]) -> Any:
        """fn() on the writer, then on the others (which find its result in the cache)."""
        return fn()

    def barrier(self) -> None:
        pass
