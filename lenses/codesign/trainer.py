"""The co-design training loop (paper Fig. 2), with caching, resume and a NaN guard.

Per step: scene crops -> lens -> sensor image; one step of the segmentation net (cross-entropy,
AdamW) and of the RED10 adversary (MSE, Adam) on the detached sensor image; then a second pass
through the updated networks steps the optics (Adam, or MTAdam) on
lambda_seg L_seg - lambda_deb L_deb (+ the gradient penalty), and projects the coefficients back
inside the bounds of the spec. A clean pre-training of the utility net on sharp scenes is shared
by all lenses and fine-tuned per lens, as the paper fine-tunes SegFormer.
"""

from __future__ import annotations

import dataclasses
import logging
import math
import time
from dataclasses import dataclass
from pathlib import Path
from typing import Any, Callable

import torch
import torch.nn.functional as F
from tqdm.auto import tqdm

from attacks.networks.red10 import RED10
from benchmark.cache import config_hash
from benchmark.utility.segformer import build_segformer, segment_logits
from lenses.codesign.artifacts import (load_checkpoint, load_weights, publish_directory, save_checkpoint,
                                       save_weights, write_json)
from lenses.codesign.data import CropSampler, step_generator
from lenses.codesign.mtadam import MTAdam
from lenses.codesign.schemes import Scheme
from lenses.bound import fano_ceiling, noise_to_signal, plate_bits
from lenses.lens import Lens
from lenses.spec import LensSpec, load_spec, spec_to_toml

log = logging.getLogger(__name__)

IGNORE = 255
# Bumped whenever the loop changes what it computes, so stale cache entries are not reused.
TRAINER_VERSION = 1


class TrainingDivergedError(RuntimeError):
    """A loss became NaN or Inf; the last good checkpoint is kept."""


class SingleProcess:
    """How one training step is spread over replicas: here, one process holds the whole batch.

    The loop is written against this interface so that `lenses.codesign.distributed.DataParallel`
    can split each batch over ranks; every method here is an exact identity, so single-process
    training computes bit for bit what it did before data parallelism existed.
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

    def gradient_penalty(self, g: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor]:
        """(penalty value, term to add to this replica's optics loss) for dL_deb/dtheta estimate g."""
        penalty = (g.norm() - 1.0) ** 2
        return penalty, penalty

    def mtadam(self, params: list[torch.Tensor], lr: float) -> torch.optim.Optimizer:
        return MTAdam(params, lr=lr)

    def writer_first(self, fn: Callable[[], Any]) -> Any:
        """fn() on the writer, then on the others (which find its result in the cache)."""
        return fn()

    def barrier(self) -> None:
        pass


@dataclass
class TrainedLens:
    """A lens together with the networks trained with it."""

    lens: Lens
    utility_net: torch.nn.Module
    adversary: torch.nn.Module | None
    record: dict[str, Any]
    directory: Path


def psf_radius_px(psf: torch.Tensor) -> float:
    """Energy-weighted RMS radius of a (3,K,K) PSF about its centroid, in pixels (channel mean)."""
    k = psf.shape[-1]
    yy, xx = torch.meshgrid(torch.arange(k, dtype=psf.dtype), torch.arange(k, dtype=psf.dtype), indexing="ij")
    radii = []
    for p in psf.detach().cpu():
        cy, cx = float((p * yy).sum()), float((p * xx).sum())
        radii.append(float(torch.sqrt((p * ((yy - cy) ** 2 + (xx - cx) ** 2)).sum())))
    return sum(radii) / len(radii)


def _profile_fields(profile: Any, names: tuple[str, ...]) -> dict[str, Any]:
    return {n: getattr(profile, n) for n in names}


_DATA_FIELDS = ("image_size", "n_train", "train_crop", "batch_size")


def pretrain_utility(profile: Any, seed: int, device: str, cache_dir: Path, scene_set: str = "synthetic",
                     progress: bool = True) -> torch.nn.Module:
    """The clean utility net: SegFormer trained on sharp scenes, cached once per (profile, seed)."""
    config = {"what": "clean-utility", "version": TRAINER_VERSION, "model": profile.utility_model,
              "steps": profile.pretrain_steps, "lr": profile.seg_lr, "scenes": scene_set, "seed": seed,
              **_profile_fields(profile, _DATA_FIELDS)}
    path = Path(cache_dir) / "utility" / f"clean-{profile.utility_model}-{config_hash(config)}.safetensors"
    torch.manual_seed(seed)
    net = build_segformer(profile.utility_model).to(device)
    if path.is_file():
        return load_weights(path, net).eval()
    sampler = CropSampler.from_split(scene_set, profile.n_train, profile.image_size, profile.train_crop,
                                     profile.batch_size, seed)
    opt = torch.optim.AdamW(net.parameters(), lr=profile.seg_lr)
    net.train()
    bar = tqdm(range(profile.pretrain_steps), desc="clean utility pre-training", disable=not progress, leave=False)
    for step in bar:
        torch.manual_seed(seed * 7919 + step)
        x, y = sampler.batch(step, device)
        loss = F.cross_entropy(segment_logits(net, x), y, ignore_index=IGNORE)
        if not torch.isfinite(loss):
            raise TrainingDivergedError(f"clean utility pre-training diverged at step {step} (loss {float(loss)})")
        opt.zero_grad(set_to_none=True)
        loss.backward()
        opt.step()
        bar.set_postfix(ce=f"{loss.item():.3f}")
    path.parent.mkdir(parents=True, exist_ok=True)
    tmp = path.with_suffix(f".tmp{torch.randint(1 << 30, (1,)).item()}")
    save_weights(tmp, net)
    tmp.replace(path)
    return net.eval()


class CoDesign:
    """One training run: a start spec, a scheme, a profile and a seed; cached by their hash."""

    def __init__(self, start: LensSpec, scheme: Scheme, profile: Any, seed: int, device: str, cache_dir: Path,
                 name: str | None = None, scene_set: str = "synthetic", replicas: SingleProcess | None = None):
        if scheme.optics and not start.mask.trainable:
            raise ValueError(f"scheme {scheme.name!r} trains the optics, but lens spec {start.name!r} declares no "
                             "mask.bounds_um (a trainable mask declares its bounds)")
        self.start, self.scheme, self.profile, self.seed = start, scheme, profile, seed
        self.device, self.scene_set = device, scene_set
        # Deliberately not in the config hash: a data-parallel run is the same run (same global
        # batches), so `lenses.load` finds it and either kind of run resumes the other's checkpoint.
        self.replicas = replicas or SingleProcess()
        self.name = name or scheme.name
        self.config = {
            "what": "codesign", "version": TRAINER_VERSION, "scheme": dataclasses.asdict(scheme),
            "start": start.to_dict(), "seed": seed, "scenes": scene_set,
            **_profile_fields(profile, _DATA_FIELDS + ("utility_model", "adversary_width", "pretrain_steps",
                                                       "codesign_steps", "optics_lr", "seg_lr", "deb_lr")),
            **({"bound_scenes": profile.bound_scenes} if scheme.balance == "info" else {}),
        }
        root = Path(cache_dir) / "codesign"
        self.directory = root / f"{self.name}-{config_hash(self.config)}"
        self.checkpoint_path = root / f"{self.directory.name}.checkpoint.pt"
        self.cache_dir = Path(cache_dir)

    # ---- loading -------------------------------------------------------------------------------
    def load(self) -> TrainedLens | None:
        """The finished run from the cache, or None."""
        d = self.directory
        if not (d / "record.json").is_file():
            return None
        import json
        record = json.loads((d / "record.json").read_text())
        lens = Lens(load_spec(d / "lens.toml"), geometry=None).to(self.device)
        utility = load_weights(d / "utility.safetensors", build_segformer(self.profile.utility_model)).to(self.device)
        adversary = None
        if (d / "adversary.safetensors").is_file():
            adversary = load_weights(d / "adversary.safetensors", RED10(self.profile.adversary_width)).to(self.device)
            adversary.eval()
        utility.eval()
        return TrainedLens(lens, utility, adversary, record, d)

    def load_or_train(self, progress: bool = True) -> TrainedLens:
        return self.load() or self.train(progress=progress)

    # ---- training ------------------------------------------------------------------------------
    def train(self, progress: bool = True, stop_after: int | None = None,
              on_step: Callable[[int, dict], None] | None = None) -> TrainedLens:
        """Train (resuming from the last checkpoint if one exists) and publish the artifacts.

        `stop_after` ends the call after that many steps of this call, leaving the checkpoint
        (used by tests to simulate an interruption).
        """
        p, scheme, dev, rep = self.profile, self.scheme, self.device, self.replicas
        t_start = time.perf_counter()
        progress = progress and rep.is_writer
        clean = rep.writer_first(lambda: pretrain_utility(p, self.seed, dev, self.cache_dir, self.scene_set, progress))
        torch.manual_seed(self.seed)
        lens = Lens(self.start).to(dev)
        seg = build_segformer(p.utility_model).to(dev)
        seg.load_state_dict(clean.state_dict())
        deb = RED10(p.adversary_width).to(dev) if scheme.adversary else None
        seg_fit = rep.fitting(seg)
        deb_fit = rep.fitting(deb) if deb is not None else None
        opt_seg = torch.optim.AdamW(seg.parameters(), lr=p.seg_lr)
        opt_deb = torch.optim.Adam(deb.parameters(), lr=p.deb_lr) if deb is not None else None
        opt_opt: torch.optim.Optimizer | None = None
        if scheme.optics:
            params = [lens.coefficients_um]
            opt_opt = rep.mtadam(params, p.optics_lr) if scheme.balance == "mtadam" else torch.optim.Adam(params, lr=p.optics_lr)
        curves: dict[str, list] = {"step": [], "seg": [], "deb": [], "gp": [], "bits": [], "coefficients_um": [],
                                   "psf_radius_px": []}
        start_step = 0
        ckpt = load_checkpoint(self.checkpoint_path)
        if ckpt is not None:
            start_step = int(ckpt["step"])
            with torch.no_grad():
                lens.coefficients_um.copy_(ckpt["coefficients_um"])
            seg.load_state_dict(ckpt["seg"])
            opt_seg.load_state_dict(ckpt["opt_seg"])
            if deb is not None:
                deb.load_state_dict(ckpt["deb"])
                opt_deb.load_state_dict(ckpt["opt_deb"])  # type: ignore[union-attr]
            if opt_opt is not None:
                opt_opt.load_state_dict(ckpt["opt_optics"])
            curves = ckpt["curves"]
            log.info("%s: resuming from step %d (%s)", self.name, start_step, self.checkpoint_path)
        rep.barrier()  # every replica has read the checkpoint before the writer may replace it
        sampler = CropSampler.from_split(self.scene_set, p.n_train, p.image_size, p.train_crop, p.batch_size,
                                         self.seed)
        if scheme.balance == "info":
            from benchmark.plate_spectrum import cached_plate_spectrum
            from benchmark.scenes import plate_entropy_bits
            self.spectrum = rep.writer_first(lambda: cached_plate_spectrum(self.cache_dir, p.bound_scenes, seed=self.seed))
            self.entropy_bits = plate_entropy_bits()
        every = max(1, p.codesign_steps // 10)
        seg.train()
        if deb is not None:
            deb.train()
        bar = tqdm(range(start_step, p.codesign_steps), desc=f"co-design {self.name}", disable=not progress,
                   initial=start_step, total=p.codesign_steps, leave=False)
        done_here = 0
        for step in bar:
            stats = self._step(step, lens, seg, deb, opt_seg, opt_deb, opt_opt, sampler, seg_fit, deb_fit)
            curves["step"].append(step)
            for key in ("seg", "deb", "gp", "bits"):
                curves[key].append(stats.get(key, math.nan))
            curves["coefficients_um"].append([float(c) for c in lens.coefficients_um.detach().cpu()])
            curves["psf_radius_px"].append(stats["psf_radius_px"])
            bar.set_postfix({k: f"{v:.3g}" for k, v in stats.items() if k not in ("psf_radius_px", "ceiling")})
            if on_step is not None:
                on_step(step, stats)
            done_here += 1
            last = step + 1 == p.codesign_steps
            if rep.is_writer and ((step + 1) % every == 0 or last):
                state = {"step": step + 1, "coefficients_um": lens.coefficients_um.detach().cpu(),
                         "seg": seg.state_dict(), "opt_seg": opt_seg.state_dict(), "curves": curves}
                if deb is not None:
                    state.update(deb=deb.state_dict(), opt_deb=opt_deb.state_dict())  # type: ignore[union-attr]
                if opt_opt is not None:
                    state["opt_optics"] = opt_opt.state_dict()
                save_checkpoint(self.checkpoint_path, state)
            if stop_after is not None and done_here >= stop_after and not last:
                raise KeyboardInterrupt(f"stopped after {done_here} steps (checkpoint kept)")
        record = {"name": self.name, "scheme": self.scheme.name, "config": self.config, "curves": curves,
                  "train_s": time.perf_counter() - t_start, "seconds_per_step": None,
                  "final_coefficients_um": [float(c) for c in lens.coefficients_um.detach().cpu()],
                  "psf_radius_px": psf_radius_px(lens.psf()), "world_size": rep.world}
        if done_here:
            record["seconds_per_step"] = (time.perf_counter() - t_start) / done_here
        if rep.is_writer:
            self._publish(lens, seg, deb, record)
            self.checkpoint_path.unlink(missing_ok=True)
        rep.barrier()  # the others load what the writer published
        trained = self.load()
        assert trained is not None
        return trained

    def _step(self, step: int, lens: Lens, seg: torch.nn.Module, deb: torch.nn.Module | None,
              opt_seg: torch.optim.Optimizer, opt_deb: torch.optim.Optimizer | None,
              opt_opt: torch.optim.Optimizer | None, sampler: CropSampler, seg_fit: torch.nn.Module | None = None,
              deb_fit: torch.nn.Module | None = None) -> dict[str, float]:
        """One step on batch `step`. `seg_fit`/`deb_fit` (default: seg/deb) run the networks' own
        training pass; the optics pass goes through the bare modules. Under data parallelism every
        loss here is this replica's estimate of the global-batch loss (see SingleProcess.scale)."""
        scheme, dev, rep = self.scheme, self.device, self.replicas
        seg_fit = seg if seg_fit is None else seg_fit
        deb_fit = deb if deb_fit is None else deb_fit
        torch.manual_seed(self.seed * 7919 + step)  # drop-path etc.: reproducible across resumes
        x, y = sampler.batch(step, dev)
        rows = rep.rows(len(x))
        sensor = rep.sense(lens, x, rows, step_generator(self.seed, step, dev))
        w_seg, w_deb = rep.scale((y != IGNORE).sum()), rep.scale(x.numel())
        x, y = x[rows], y[rows]

        def seg_loss(net: torch.nn.Module, images: torch.Tensor) -> torch.Tensor:
            return F.cross_entropy(segment_logits(net, images), y, ignore_index=IGNORE, reduction=rep.reduction) * w_seg

        def deb_loss(net: torch.nn.Module, images: torch.Tensor) -> torch.Tensor:
            return F.mse_loss(net(images), x, reduction=rep.reduction) * w_deb

        # 1) the networks, on the detached sensor image
        loss_seg = seg_loss(seg_fit, sensor.detach())
        stats = {"seg": rep.item(loss_seg.detach())}
        opt_seg.zero_grad(set_to_none=True)
        loss_seg.backward()
        opt_seg.step()
        if deb is not None:
            loss_deb = deb_loss(deb_fit, sensor.detach())
            stats["deb"] = rep.item(loss_deb.detach())
            opt_deb.zero_grad(set_to_none=True)  # type: ignore[union-attr]
            loss_deb.backward()
            opt_deb.step()  # type: ignore[union-attr]
        self._guard(step, stats)
        # 2) the optics, through the updated networks
        if opt_opt is not None:
            coeffs = lens.coefficients_um
            seg_term = scheme.lambda_seg * seg_loss(seg, sensor)
            if scheme.balance == "info":
                nsr = noise_to_signal(lens, self.spectrum.mean_radiance)
                bits = plate_bits(lens.psf(), self.spectrum, scheme.info_width_px, nsr)
                ceiling = (bits + 1.0) / self.entropy_bits  # unclipped: keeps its gradient above 1
                stats["bits"] = bits.item()
                stats["ceiling"] = float(fano_ceiling(bits.item(), self.entropy_bits))
                total = seg_term + scheme.lambda_info * torch.relu(ceiling - scheme.info_eps)
            elif deb is None:
                total = seg_term
            else:
                deb_term = deb_loss(deb, sensor)
                total = seg_term - scheme.lambda_deb * deb_term
                if scheme.balance == "gp":
                    (g,) = torch.autograd.grad(deb_term, coeffs, create_graph=True)
                    penalty, term = rep.gradient_penalty(g)
                    stats["gp"] = penalty.item()
                    total = total + term
            self._guard(step, {"optics": rep.item(total.detach())})
            if scheme.balance == "mtadam":
                # MTAdam balances the terms itself: L_seg is the anchor, -lambda_deb L_deb is rescaled to it.
                opt_opt.step([seg_term, -scheme.lambda_deb * deb_term])  # type: ignore[call-arg]
            else:
                (grad,) = torch.autograd.grad(total, coeffs)
                opt_opt.zero_grad(set_to_none=True)
                coeffs.grad = rep.mean(grad)
                opt_opt.step()
            lens.clamp_to_bounds()
        stats["psf_radius_px"] = psf_radius_px(lens.psf())
        return stats

    def _guard(self, step: int, stats: dict[str, float]) -> None:
        bad = {k: v for k, v in stats.items() if not math.isfinite(v)}
        if bad:
            raise TrainingDivergedError(
                f"co-design {self.name!r} diverged at step {step}: {bad}; the last good checkpoint is kept at "
                f"{self.checkpoint_path if self.checkpoint_path.exists() else '(none yet)'}; lower the profile's "
                "optics_lr or seg_lr and rerun (it resumes from the checkpoint)")

    def _publish(self, lens: Lens, seg: torch.nn.Module, deb: torch.nn.Module | None, record: dict) -> None:
        staging = self.directory.with_name(self.directory.name + f".staging-{torch.randint(1 << 30, (1,)).item()}")
        staging.mkdir(parents=True)
        learned = dataclasses.replace(lens.current_spec(), name=self.name,
                                      description=f"co-designed with scheme {self.scheme.name!r}, seed {self.seed}")
        (staging / "lens.toml").write_text(spec_to_toml(learned))
        save_weights(staging / "utility.safetensors", seg)
        if deb is not None:
            save_weights(staging / "adversary.safetensors", deb)
        write_json(staging / "record.json", record)
        publish_directory(staging, self.directory)
