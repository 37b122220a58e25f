"""Shared training loop and weight cache of the trained restorers (``nafnet-*``).

Recipe (NAFNet's, Chen et al. 2022, scaled to the profile's budget): loss = negative PSNR of
the clamped-free output against the sharp crop, AdamW (lr 1e-3, betas (0.9, 0.9), weight decay
1e-3), cosine schedule to 1e-7 over ``steps``. Gradients are clipped to norm 1: the PSNR loss
is ``10 log10(MSE)``, whose gradient grows as ``1 / MSE`` on an easy batch.

Trained weights are cached as safetensors (never pickle) in the fit context's artifact store
(``FitContext.artifacts``: atomic writes, verified reads), keyed by (attacker, configuration), so a
second run, or a second lens sharing a lens-independent model, loads instead of retraining.
"""

from __future__ import annotations

import dataclasses
import hashlib
import logging
import time
from collections.abc import Callable, Iterable
from typing import Any

import torch
from tqdm.auto import tqdm
from safetensors import SafetensorError
from safetensors.torch import load as load_safetensors
from safetensors.torch import save as save_safetensors
from torch import Tensor, nn

from common import crops
from attacks.base import ArtifactStore, AttackBudget
from attacks.networks.nafnet import NAFNet
from attacks.training.shipped_weights import Shipped, data_summary, find_shipped

__all__ = [
    "RestorerBudget",
    "collect_pairs",
    "data_identity",
    "fingerprint",
    "lens_key",
    "load_or_train",
    "negative_psnr",
    "random_crops",
    "shipped_or_fit",
    "train_restorer",
]

log = logging.getLogger(__name__)

_LR = 1e-3
_LR_MIN = 1e-7
_WEIGHT_DECAY = 1e-3
_BETAS = (0.9, 0.9)
_GRAD_CLIP = 1.0


@dataclasses.dataclass(frozen=True)
class RestorerBudget:
    """Size and step budget of a trained restorer, from the fit context's ``AttackBudget``.

    Attributes:
        steps: Optimiser steps.
        width, enc_blocks, middle_blocks, dec_blocks: NAFNet architecture.
        crop_px: Side of the square training crops, in pixels (even: keeps the Bayer phase).
        batch_size: Crops per step.
        max_train_images: How many training crops to draw from the TRAIN split.
    """

    steps: int
    width: int
    enc_blocks: tuple[int, ...]
    middle_blocks: int
    dec_blocks: tuple[int, ...]
    crop_px: int
    batch_size: int
    max_train_images: int

    @classmethod
    def from_budget(cls, budget: AttackBudget) -> RestorerBudget:
        """The restorer fields of an attack budget (the default ``AttackBudget()`` fits in well under a second)."""
        return cls(steps=budget.restorer_steps, width=budget.nafnet_width, enc_blocks=tuple(budget.nafnet_enc_blocks),
                   middle_blocks=budget.nafnet_middle_blocks, dec_blocks=tuple(budget.nafnet_dec_blocks),
                   crop_px=budget.crop_px, batch_size=budget.batch_size, max_train_images=budget.max_train_images)

    def nafnet_arch(self) -> dict[str, Any]:
        """Keyword arguments of ``NAFNet`` for this budget."""
        return {"width": self.width, "enc_blk_nums": self.enc_blocks, "middle_blk_num": self.middle_blocks,
                "dec_blk_nums": self.dec_blocks}

    def build_nafnet(self) -> NAFNet:
        return NAFNet(**self.nafnet_arch())

    def to_dict(self) -> dict[str, Any]:
        return dataclasses.asdict(self)


# The memory layout the restorers train in (see `train_restorer`); the model goes back to the default after.
TRAINING_LAYOUT = torch.channels_last


def negative_psnr(output: Tensor, target: Tensor) -> Tensor:
    """NAFNet's PSNR loss: mean over the batch of ``10 log10(MSE_i)`` (images in [0, 1]), i.e.
    minus the PSNR in dB; scalar."""
    mse = (output - target).pow(2).flatten(1).mean(dim=1)
    return 10.0 * torch.log10(mse + 1e-8).mean()


def collect_pairs(train_pairs: Callable[[], Iterable[tuple[Tensor, Tensor]]], max_images: int
                  ) -> tuple[Tensor, Tensor]:
    """Up to ``max_images`` (sensor, sharp) pairs from the TRAIN split, on the CPU.

    Returns:
        sensor, sharp: each (N, 3, H, W) in [0, 1].
    """
    sensors, sharps, n = [], [], 0
    for sensor, sharp in train_pairs():
        sensors.append(sensor.detach().cpu())
        sharps.append(sharp.detach().cpu())
        n += sensor.shape[0]
        if n >= max_images:
            break
    if not sensors:
        raise ValueError("FitContext.train_pairs() yielded no batches; a trained restorer needs TRAIN pairs")
    return torch.cat(sensors)[:max_images], torch.cat(sharps)[:max_images]


def random_crops(images: list[Tensor], n: int, crop_px: int, generator: torch.Generator) -> list[Tensor]:
    """The same ``n`` random square crops from each tensor of ``images`` (all (N, C, H, W), aligned),
    by the project's sampler (``common.crops``) with even offsets. Translation is the only
    augmentation, because flips or rotations would change an asymmetric PSF.

    Returns:
        One (n, C, h, w) tensor per input, h = min(crop_px, H) rounded down to even, same for w.
    """
    height, width = images[0].shape[-2:]
    h = min(crop_px, height) // 2 * 2 or height
    w = min(crop_px, width) // 2 * 2 or width
    return crops.random_crops(images, (h, w), generator, n=n)


def train_restorer(model: nn.Module, next_batch: Callable[[torch.Generator], tuple[Tensor, Tensor]],
                   steps: int, device: str, seed: int,
                   checkpoint: Callable[[int, nn.Module], None] | None = None) -> list[float]:
    """Train ``model`` in place with NAFNet's recipe (module docs).

    Args:
        model: Network, input image (B, 3, h, w) -> restored image.
        next_batch: Given a CPU generator, returns (input, target) CPU tensors (B, 3, h, w).
        steps: Optimiser steps (0 leaves the model untouched).
        device: Torch device to train on; the model is moved there and back to the CPU.
        seed: Seeds the batch generator (weights are initialised by the caller).
        checkpoint: Called as ``checkpoint(step, model)`` after every optimiser step (1-based), e.g.
            to score the model on held-out images during one long fit; it must leave the model's
            weights alone (the loop puts the model back in train mode afterwards).

    Returns:
        The loss (negative PSNR, dB) of every step.

    The steps run with the weights in channels-last layout, so the convolutions' backward copies no
    activations between layouts (faster: docs/history.md; the sums' order, so float rounding, differs); the model is handed back in the default layout, so it
    infers exactly as the same weights loaded from the cache do.
    """
    model.to(device).to(memory_format=TRAINING_LAYOUT).train()
    optimizer = torch.optim.AdamW(model.parameters(), lr=_LR, betas=_BETAS, weight_decay=_WEIGHT_DECAY)
    schedule = torch.optim.lr_scheduler.CosineAnnealingLR(optimizer, T_max=max(steps, 1), eta_min=_LR_MIN)
    generator = torch.Generator().manual_seed(seed)
    losses = []
    t0 = time.perf_counter()
    bar = tqdm(range(steps), desc="restorer fit", unit="step", leave=False)
    for step in bar:
        inp, target = next_batch(generator)
        loss = negative_psnr(model(inp.to(device)), target.to(device))
        optimizer.zero_grad(set_to_none=True)
        loss.backward()
        nn.utils.clip_grad_norm_(model.parameters(), _GRAD_CLIP)
        optimizer.step()
        schedule.step()
        losses.append(loss.item())
        bar.set_postfix(psnr_db=f"{-losses[-1]:.2f}")
        if checkpoint is not None:
            checkpoint(step + 1, model)
            model.train()
        if (step + 1) % max(steps // 10, 1) == 0:
            log.info("step %d/%d: %.2f dB (%.1f s)", step + 1, steps, -loss.item(), time.perf_counter() - t0)
    model.to(memory_format=torch.contiguous_format)
    return losses


def fingerprint(*tensors: Tensor) -> str:
    """Short SHA-256 of the tensors' bytes: identifies training data in a cache key."""
    digest = hashlib.sha256()
    for t in tensors:
        digest.update(t.detach().cpu().contiguous().numpy().tobytes())
    return digest.hexdigest()[:16]


def data_identity(*tensors: Tensor) -> dict[str, Any]:
    """What identifies training data in a cache key: ``sha256`` (``fingerprint``, exact bytes) and
    ``summary`` (``attacks.training.shipped_weights.data_summary``), which shipped weights are matched by when
    the bytes differ only by another CPU's float rounding (``attacks.training.shipped_weights.same_data``)."""
    return {"sha256": fingerprint(*tensors), "summary": data_summary(*tensors)}


def lens_key(lens: Any) -> Any:
    """What identifies a lens in a cache key: its spec with the current Zernike coefficients
    (``current_spec().to_dict()``), else its spec's ``to_dict()``; for lens-likes without either
    (test fakes) the spec's repr plus a fingerprint of the PSF and gain."""
    if hasattr(lens, "current_spec"):
        return lens.current_spec().to_dict()
    if hasattr(lens.spec, "to_dict"):
        return lens.spec.to_dict()
    return {"spec": repr(lens.spec), "psf_gain": fingerprint(lens.psf().detach(), lens.gain().detach())}


def load_or_train(model: nn.Module, artifacts: ArtifactStore | None, kind: str, key: dict[str, Any],
                  train: Callable[[nn.Module], object]) -> bool:
    """Load ``model``'s weights from the artifact store, or train them and store them.

    Args:
        model: Freshly initialised network; weights are loaded or trained in place.
        artifacts: The fit context's store (None: always train, store nothing).
        kind: Artifact kind naming the attacker, e.g. "nafnet-known-pairs".
        key: JSON-serialisable configuration that determines the weights.
        train: Trains ``model`` in place.

    Returns:
        True if the model was trained, False if it came from the store.
    """
    data = None if artifacts is None else artifacts.load(kind, key)
    if data is not None:
        try:
            model.load_state_dict(load_safetensors(data), strict=True)
            log.info("%s: weights loaded from the cache", kind)
            return False
        except (SafetensorError, RuntimeError, KeyError) as exc:  # verified bytes of another layout
            log.warning("%s: cached weights do not fit the network (%s); retraining", kind, exc)
    train(model)
    if artifacts is not None:
        state = {k: v.detach().cpu().contiguous() for k, v in model.state_dict().items()}
        artifacts.save(kind, key, save_safetensors(state, metadata={"kind": kind}))
    return True


def fit_nafnet(budget: RestorerBudget, ctx: Any, kind: str, key: dict[str, Any],
               next_batch: Callable[[torch.Generator], tuple[Tensor, Tensor]]) -> tuple[NAFNet, bool]:
    """A NAFNet of the budget's size, seeded with ``ctx.seed``, loaded from or trained into the cache.

    Returns the network and whether it was trained (False: the cached weights were loaded).
    """
    with torch.random.fork_rng(devices=[]):
        torch.manual_seed(ctx.seed)
        model = budget.build_nafnet()
    trained = load_or_train(model, ctx.artifacts, kind, key,
                            lambda m: train_restorer(m, next_batch, budget.steps, ctx.device, ctx.seed))
    return model, trained


def shipped_or_fit(budget: RestorerBudget, ctx: Any, kind: str, key: dict[str, Any],
                   next_batch: Callable[[torch.Generator], tuple[Tensor, Tensor]], use_shipped: bool = True
                   ) -> tuple[NAFNet, bool, Shipped | None]:
    """The package's weights shipped for exactly ``key`` (``attacks.training.shipped_weights``), else ``fit_nafnet``.

    Returns the network, whether it was trained now, and the shipped weights used (None if none).
    """
    shipped = find_shipped(kind, key) if use_shipped else None
    if shipped is None:
        model, trained = fit_nafnet(budget, ctx, kind, key, next_batch)
        return model, trained, None
    model = budget.build_nafnet()
    model.load_state_dict(load_safetensors(shipped.data), strict=True)
    log.info("%s: weights shipped with the package (%s)", kind, shipped.path.name)
    return model, False, shipped
