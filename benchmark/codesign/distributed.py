"""Data-parallel co-design over torch.distributed ranks (torchrun; gloo on the CPU, NCCL on GPUs).

`DataParallel` plugs into `CoDesign(..., replicas=...)` and is built to compute the
single-process step on the same global batch, up to float reduction order:

- Batch: every rank draws the whole batch of step s (`CropSampler.batch(step)`, cheap) and
  trains on one contiguous block of its rows: with B rows and W ranks, rank r gets
  torch.tensor_split's r-th block (rows [r B/W, (r+1) B/W) when W divides B).
- Sensor noise: every rank draws it for the whole batch from `step_generator(seed, step)` (the
  other rows' irradiance is zero, and the sensor is cheap next to the networks) and keeps its rows.
- Losses: each rank's loss is its estimate of the global-batch mean: its local sum times W over
  the global count (non-ignored pixels for the cross-entropy, elements for the MSE). The mean over
  ranks of these estimates is the global mean, so DDP's averaged network gradients and the
  explicitly averaged optics gradient are those of the global batch, also when a rank's crops hold
  more ignored pixels than another's.
- SegFormer internals: drop-path and dropout draw their masks for the global batch from the global
  RNG (seeded alike on every rank by the loop) and keep their rows, so each sample gets the mask it
  gets in a single process; batch norm normalises by the global batch's statistics (a
  differentiable all-reduce of sums and sums of squares), so its running statistics agree too.
- Optics: every term's coefficient gradient is averaged over ranks (`mean`), so Adam steps on
  the global gradient and MTAdam balances the global terms. The gradient penalty is the global
  batch's: G = dL_deb/dtheta is averaged over ranks first, P = (||G|| / r - 1)^2 (r the reference norm, global), and each rank adds g_r . v (v = dP/dG, g_r its
  own estimate of G, still differentiable), whose gradient averaged over ranks is exactly dP/dtheta.
  Every rank then applies the same update to the same all-reduced gradient, so the coefficients
  stay bitwise identical without a broadcast.
- Writing: rank 0 alone pre-trains the clean utility net (not data-parallel; the others wait at a
  barrier, hence the long process-group timeout), writes checkpoints and publishes the finished
  directory; the others then load it. Every rank reads the same checkpoint when resuming.
"""

from __future__ import annotations

import datetime
import os
from collections.abc import Callable, Iterator
from contextlib import contextmanager
from dataclasses import dataclass, field
from typing import Any

import torch
import torch.distributed as dist
import torch.nn.functional as F
from torch import nn
from torch.distributed import _functional_collectives as funcol  # differentiable collectives
from torch.nn.parallel import DistributedDataParallel
from transformers.models.segformer.modeling_segformer import SegformerDropPath

from benchmark.codesign.replicas import SingleProcess
from lenses.lens import Lens

__all__ = ["DataParallel", "launched_by_torchrun", "session"]

# Non-writers wait at a barrier while rank 0 alone pre-trains the clean utility net (hours on the
# paper profile); a crashed rank ends the others through torchrun long before this.
PROCESS_GROUP_TIMEOUT = datetime.timedelta(hours=12)


def launched_by_torchrun() -> bool:
    """True when torchrun's RANK, WORLD_SIZE and LOCAL_RANK are all set."""
    return all(v in os.environ for v in ("RANK", "WORLD_SIZE", "LOCAL_RANK"))


@contextmanager
def session(device: str) -> Iterator[tuple[DataParallel | None, str]]:
    """(replicas, this rank's device) for a training run, then the process group destroyed.

    Under torchrun the process group is initialised from the environment with gloo for
    `device` "cpu" or NCCL for "cuda[:N]" (this rank then uses cuda:LOCAL_RANK); otherwise this
    yields (None, device): plain single-process training.
    """
    if not launched_by_torchrun():
        yield None, device
        return
    if device == "cpu":
        backend = "gloo"
    elif device.startswith("cuda"):
        local_rank = int(os.environ["LOCAL_RANK"])
        torch.cuda.set_device(local_rank)
        backend, device = "nccl", f"cuda:{local_rank}"
    else:
        raise ValueError(f"data-parallel training runs on device cpu (gloo) or cuda (NCCL), got {device!r}")
    dist.init_process_group(backend, timeout=PROCESS_GROUP_TIMEOUT)
    try:
        yield DataParallel(device), device
    finally:
        dist.destroy_process_group()


@dataclass
class _Rows:
    """This rank's rows of the current global batch, shared by the global-batch layers."""

    rows: slice = field(default_factory=lambda: slice(0, 0))
    total: int = 0

    def check(self, h: torch.Tensor) -> None:
        if h.shape[0] != self.rows.stop - self.rows.start:
            raise RuntimeError(f"a global-batch layer got {h.shape[0]} rows but this rank holds rows {self.rows} "
                               f"of {self.total}; call DataParallel.rows(batch_size) for each new batch")


class _GlobalDropPath(nn.Module):
    """transformers' SegformerDropPath with its per-sample keep mask drawn for the global batch."""

    def __init__(self, drop_prob: float, layout: _Rows):
        super().__init__()
        self.drop_prob, self.layout = drop_prob, layout

    def forward(self, h: torch.Tensor) -> torch.Tensor:
        if not self.training:
            return h
        self.layout.check(h)
        keep = 1 - self.drop_prob
        draw = torch.rand((self.layout.total,) + (1,) * (h.ndim - 1), dtype=h.dtype, device=h.device)
        return h.div(keep) * torch.floor(draw[self.layout.rows] + keep)


class _GlobalDropout(nn.Module):
    """nn.Dropout with its mask drawn for the global batch: dropout itself applied to ones.

    The draw follows the memory layout (ATen's mask is empty_like(input)), so the ones take this
    rank's strides. A rank holding two rows or more sees the layout of the global batch and each
    sample gets the mask it gets in a single process; with one row, CPU kernels may lay the
    activation out differently, and the masks are other, equally distributed draws.
    """

    def __init__(self, p: float, layout: _Rows):
        super().__init__()
        self.p, self.layout = p, layout

    def forward(self, h: torch.Tensor) -> torch.Tensor:
        if not self.training:
            return h
        self.layout.check(h)
        if h.stride(0) != h[0].numel():
            raise NotImplementedError(f"global-batch dropout needs the batch as the outermost dimension, got strides {h.stride()}")
        ones = torch.empty_strided((self.layout.total,) + h.shape[1:], h.stride(), dtype=h.dtype, device=h.device)
        return h * F.dropout(ones.fill_(1.0), self.p, training=True)[self.layout.rows]


class _GlobalBatchNorm2d(nn.BatchNorm2d):
    """BatchNorm2d that, in training, normalises by the mean and variance of all ranks' rows.

    Sums and sums of squares (float64) are all-reduced differentiably, so gradients flow to every
    rank's activations as in a single process. State dict and eval behaviour are BatchNorm2d's.
    """

    def __init__(self, bn: nn.BatchNorm2d, group: Any):
        super().__init__(bn.num_features, bn.eps, bn.momentum, bn.affine, bn.track_running_stats,
                         device=bn.weight.device if bn.affine else None)
        self.load_state_dict(bn.state_dict())
        self.train(bn.training)
        self.group = group

    def forward(self, x: torch.Tensor) -> torch.Tensor:
        if not self.training:
            return super().forward(x)
        c = x.shape[1]
        wide = x.double()
        local = torch.cat([wide.sum((0, 2, 3)), wide.square().sum((0, 2, 3)), wide.new_tensor([x.numel() // c])])
        stats = funcol.wait_tensor(funcol.all_reduce(local, "sum", self.group))
        n = stats[-1]
        mean = stats[:c] / n
        var = (stats[c:2 * c] / n - mean.square()).clamp_min(0.0)
        if self.track_running_stats:
            with torch.no_grad():
                self.num_batches_tracked.add_(1)
                m = 1.0 / float(self.num_batches_tracked) if self.momentum is None else self.momentum
                self.running_mean.mul_(1 - m).add_(mean.to(x.dtype), alpha=m)
                self.running_var.mul_(1 - m).add_((var * n / (n - 1)).to(x.dtype), alpha=m)
        shape = (1, c, 1, 1)
        out = (x - mean.to(x.dtype).view(shape)) * torch.rsqrt(var + self.eps).to(x.dtype).view(shape)
        return out * self.weight.view(shape) + self.bias.view(shape) if self.affine else out


def _globalise(module: nn.Module, layout: _Rows, group: Any) -> None:
    """Swap, in place, every layer that couples or randomises the samples of a batch for its global-batch version."""
    for name, child in module.named_children():
        if isinstance(child, SegformerDropPath):
            setattr(module, name, _GlobalDropPath(child.drop_prob, layout) if child.drop_prob > 0 else child)
        elif type(child) is nn.Dropout:
            setattr(module, name, _GlobalDropout(child.p, layout) if child.p > 0 else child)
        elif type(child) is nn.BatchNorm2d:
            setattr(module, name, _GlobalBatchNorm2d(child, group))
        elif isinstance(child, (nn.modules.dropout._DropoutNd, nn.modules.batchnorm._BatchNorm)):
            raise NotImplementedError(f"data-parallel co-design has no global-batch version of {type(child).__name__} "
                                      f"({name}); it handles nn.Dropout, nn.BatchNorm2d and SegformerDropPath")
        else:
            _globalise(child, layout, group)


class DataParallel(SingleProcess):
    """The co-design step spread over the ranks of the initialised default process group."""

    reduction = "sum"

    def __init__(self, device: str):
        if not dist.is_initialized():
            raise RuntimeError("DataParallel needs an initialised process group; launch with torchrun and use session()")
        self.device = torch.device(device)
        self.rank, self.world = dist.get_rank(), dist.get_world_size()
        self.is_writer = self.rank == 0
        # Batch-norm statistics go through their own group, apart from DDP's gradient buckets.
        self._stats_group = dist.new_group()
        self._layout = _Rows()

    def rows(self, batch_size: int) -> slice:
        if batch_size < self.world:
            raise ValueError(f"batch size {batch_size} is smaller than the {self.world} data-parallel ranks; "
                             f"use at most {batch_size} processes or a profile with a larger batch_size")
        base, extra = divmod(batch_size, self.world)
        start = self.rank * base + min(self.rank, extra)
        self._layout.rows, self._layout.total = slice(start, start + base + (self.rank < extra)), batch_size
        return self._layout.rows

    def scale(self, count: torch.Tensor | int) -> float | torch.Tensor:
        return self.world / count

    def sense(self, lens: Lens, x: torch.Tensor, rows: slice, generator: torch.Generator) -> torch.Tensor:
        irradiance = lens.irradiance(x[rows])
        blank = irradiance.new_zeros
        full = torch.cat([blank((rows.start,) + irradiance.shape[1:]), irradiance,
                          blank((len(x) - rows.stop,) + irradiance.shape[1:])])
        return lens.sensor(full, generator=generator)[rows]

    def fitting(self, module: torch.nn.Module) -> torch.nn.Module:
        _globalise(module, self._layout, self._stats_group)
        # Buffers (batch-norm running statistics) agree by construction: no broadcast needed.
        device_ids = [self.device.index] if self.device.type == "cuda" else None
        return DistributedDataParallel(module, device_ids=device_ids, forward_sync_buffers=False)

    def mean(self, t: torch.Tensor) -> torch.Tensor:
        total = t.detach().clone()
        dist.all_reduce(total)
        return total / self.world

    def item(self, t: torch.Tensor) -> float:
        return float(self.mean(t))

    def gradient_penalty(self, g: torch.Tensor, reference: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor]:
        mean = self.mean(g).requires_grad_()
        penalty = (mean.norm() / reference - 1.0) ** 2
        (v,) = torch.autograd.grad(penalty, mean)
        return penalty.detach(), (g * v).sum()

    def writer_first(self, fn: Callable[[], Any]) -> Any:
        result = fn() if self.is_writer else None
        self.barrier()
        return result if self.is_writer else fn()

    def barrier(self) -> None:
        dist.barrier()
