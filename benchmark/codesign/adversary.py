"""An adversary that is strong from the start: RED10 pre-trained on the starting lens.

The paper introduces the gradient penalty because the deblurring adversary "converges too fast";
an adversary trained from random weights alongside the optics never gets there within our
budgets (20.1 dB on the quick gp lens, below the 29.2 dB of the white-balanced sensor image).
So before co-design the adversary is trained on (sensor image, sharp scene) pairs of the starting
lens until it beats the trivial attack, the white-balanced sensor image (sensor / per-channel
gain, clamped to [0, 1]), by MARGIN_DB on a fixed probe set of crops, checked every CHECK_EVERY
steps, for at most MAX_STEPS. The probe and the pre-training batches are drawn from the training
scenes on their own streams (never the co-design batches), sensor noise included, so the result
is a pure function of the starting lens, the profile and the seed, cached like the clean
utility net and shared by every scheme that starts there.

The adversary is RED10 with RED-Net's symmetric skips and a residual on the white-balanced input
(`attacks.networks.red10`): the paper's skip-less RED10 cannot beat the white-balanced image at
all (measured there).
"""

from __future__ import annotations

import logging
from pathlib import Path
from typing import Any

import torch
import torch.nn.functional as F
from tqdm.auto import tqdm

from attacks.networks.red10 import RED10
from attacks.training.restorer_training import TRAINING_LAYOUT
from benchmark.store.cache import config_hash
from benchmark.codesign.artifacts import load_weights, read_json, save_weights, write_json
from benchmark.codesign.data import CropSampler, step_generator
from benchmark.results.metrics import psnr
from lenses.lens import Lens

log = logging.getLogger(__name__)

MARGIN_DB = 1.0          # the adversary must beat the white-balanced sensor image by this much
CHECK_EVERY = 25         # pre-training steps between probe measurements
MAX_STEPS = 2000         # give up (and say so in the record) after this many steps
PROBE_BATCHES = 4        # probe set: this many batches of the profile's crops
# Batch indices of the probe and of the pre-training: far beyond any co-design step.
_PROBE_STREAM, _PRETRAIN_STREAM = 1 << 40, 1 << 41
VERSION = 1


def build_adversary(width: int, lens: Lens | None = None) -> RED10:
    """The co-design adversary: RED10 with skips, a residual on the input divided by the lens's gain."""
    net = RED10(width, skips=True, residual=True)
    if lens is not None:
        with torch.no_grad():
            net.input_gain.copy_(lens.gain().detach().to(net.input_gain))
    return net


def for_training(net: RED10, device: str) -> RED10:
    """``net`` on ``device`` in channels-last layout, as the co-design trains it: with its weights in
    the default layout every convolution's backward copied its activations into another layout first (6
    copies of 16 MB a quick step), which channels-last avoids: a quick gp co-design step runs a few per
    cent faster (docs/costs.md; docs/history.md). The values are the same; ``save_weights`` stores them
    contiguous, and evaluation loads them into a default-layout net.
    The layout is the restorer fits' (``attacks.training.restorer_training.TRAINING_LAYOUT``), for the same reason."""
    return net.to(device).to(memory_format=TRAINING_LAYOUT)


def white_balanced(sensor: torch.Tensor, lens: Lens) -> torch.Tensor:
    """The trivial attack: sensor (B,3,H,W) divided by the per-channel gain, clamped to [0, 1]."""
    return lens.white_balance(sensor)


class Probe:
    """A fixed set of training crops on which the adversary and the white-balanced image are scored."""

    def __init__(self, sampler: CropSampler, seed: int, device: str):
        self.seed, self.device = seed, device
        self.scenes = [sampler.batch(_PROBE_STREAM + i, device)[0] for i in range(PROBE_BATCHES)]

    @torch.no_grad()
    def measure(self, lens: Lens, adversary: torch.nn.Module) -> dict[str, float]:
        """Mean PSNR (dB) over the probe crops of the adversary's output (clamped to [0, 1]) and of
        the white-balanced sensor image, each against the sharp crop; sensor noise is the probe's own."""
        was_training = adversary.training
        adversary.eval()
        ours, trivial = [], []
        for i, x in enumerate(self.scenes):
            sensor = lens(x, generator=step_generator(self.seed, _PROBE_STREAM + i, self.device))
            ours.append(psnr(adversary(sensor).clamp(0.0, 1.0), x))
            trivial.append(psnr(white_balanced(sensor, lens), x))
        adversary.train(was_training)
        return {"adversary_psnr_db": float(torch.cat(ours).mean()),
                "white_balanced_psnr_db": float(torch.cat(trivial).mean())}


def pretrain_adversary(lens: Lens, sampler: CropSampler, profile: Any, seed: int, device: str, cache_dir: Path,
                       scene_set: str, progress: bool = True) -> tuple[RED10, dict[str, Any]]:
    """The adversary pre-trained on `lens` (see the module docstring) and its record: steps, whether
    it reached the margin, and its probe PSNR curve. Cached under cache_dir/adversary/."""
    config = {"what": "adversary-pretrain", "version": VERSION, "lens": lens.current_spec().to_dict(),
              "width": profile.adversary_width, "lr": profile.deb_lr, "crop": profile.train_crop,
              "batch_size": profile.batch_size, "n_train": profile.n_train, "image_size": profile.image_size,
              "seed": seed, "margin_db": MARGIN_DB, "check_every": CHECK_EVERY, "max_steps": MAX_STEPS,
              "scenes": scene_set}
    path = Path(cache_dir) / "adversary" / f"red10-{config_hash(config)}.safetensors"
    record_path = path.with_suffix(".json")
    torch.manual_seed(seed)
    net = for_training(build_adversary(profile.adversary_width, lens), device)
    if path.exists() or record_path.exists():
        cached_record = read_json(record_path)
        loaded = load_weights(path, net) if cached_record is not None else None
        if cached_record is not None and loaded is not None:
            return loaded, cached_record
        # A corrupt file was reported (with its path) as it was read; one not yet written (another run
        # is pre-training the same adversary) is simply absent: either way, train.
        torch.manual_seed(seed)  # a fresh net, as an empty cache would start (the failed load may have filled some)
        net = for_training(build_adversary(profile.adversary_width, lens), device)
    probe = Probe(sampler, seed, device)
    opt = torch.optim.Adam(net.parameters(), lr=profile.deb_lr)
    curve = [{"step": 0, **probe.measure(lens, net)}]
    net.train()
    bar = tqdm(total=MAX_STEPS, desc="adversary pre-training", disable=not progress, leave=False)
    step = 0
    while step < MAX_STEPS and curve[-1]["adversary_psnr_db"] < curve[-1]["white_balanced_psnr_db"] + MARGIN_DB:
        x, _ = sampler.batch(_PRETRAIN_STREAM + step, device)
        with torch.no_grad():
            sensor = lens(x, generator=step_generator(seed, _PRETRAIN_STREAM + step, device))
        loss = F.mse_loss(net(sensor), x)
        opt.zero_grad(set_to_none=True)
        loss.backward()
        opt.step()
        step += 1
        bar.update(1)
        if step % CHECK_EVERY == 0:
            curve.append({"step": step, **probe.measure(lens, net)})
            bar.set_postfix(adv=f"{curve[-1]['adversary_psnr_db']:.2f} dB",
                            wb=f"{curve[-1]['white_balanced_psnr_db']:.2f} dB")
    bar.close()
    last = curve[-1]
    reached = last["adversary_psnr_db"] >= last["white_balanced_psnr_db"] + MARGIN_DB
    if not reached:
        log.warning("adversary pre-training stopped after %d steps at %.2f dB, short of the white-balanced image "
                    "(%.2f dB) + %.1f dB", step, last["adversary_psnr_db"], last["white_balanced_psnr_db"], MARGIN_DB)
    record = {"steps": step, "margin_db": MARGIN_DB, "reached": reached, "curve": curve}
    write_json(record_path, record)
    save_weights(path, net)
    return net, record
