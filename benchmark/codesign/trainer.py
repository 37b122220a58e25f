"""The co-design training loop (paper Fig. 2), with caching, resume and a NaN guard.

Start: the mask from a small seeded random draw (`coefficients`), the utility net from the clean
net trained on sharp scenes (shared by all lenses, fine-tuned per lens, as the paper fine-tunes
SegFormer), the RED10 adversary pre-trained on the starting lens until it beats the
white-balanced sensor image (`adversary`).

Per step: scene crops -> lens -> sensor image; one step of the segmentation net (cross-entropy,
AdamW) and of the adversary (MSE, Adam) on the detached sensor image; then a second pass
through the updated networks steps the optics with the scheme's balancing method
(`balancing`) and projects the coefficients back inside the bounds of the spec. Every step's
numbers go to the run's curves (`curves`: JSON lines, TensorBoard events, a chart).

`CoDesign.train` reads as its four parts: `_setup` (lens, networks, optimisers), `_restore` /
`_save_checkpoint` (resume after an interruption), `_loop` (the steps) and `_finish` (record and
publish).
"""

from __future__ import annotations

import copy
import dataclasses
import logging
import math
import shutil
import time
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Callable

import torch
import torch.nn.functional as F
from tqdm.auto import tqdm

from benchmark.store.cache import config_hash, discard, write_verified
from benchmark.codesign.adversary import MARGIN_DB, Probe, build_adversary, pretrain_adversary
from benchmark.codesign.artifacts import load_checkpoint, load_weights, publish_directory, read_json, save_checkpoint, save_weights, verified, write_json
from benchmark.codesign.balancing import Balance, OpticsContext, settings
from benchmark.codesign.coefficients import INITIAL_AMPLITUDE_UM, bound_limited, initial_coefficients, noll_name
from benchmark.codesign.curves import PUBLISHED_FILES, CurveLog
from benchmark.codesign.data import CropSampler, step_generator
from benchmark.codesign.replicas import SingleProcess
from benchmark.codesign.schemes import Scheme
from benchmark.codesign.shipped import install_shipped
from benchmark.codesign.utility.clean import clean_utility_id, clean_utility_net
from benchmark.codesign.utility.segformer import build_segformer, segment_logits
from lenses.lens import Lens
from lenses.spec import LensSpec, load_spec, spec_to_toml

__all__ = ["CoDesign", "SingleProcess", "TrainedLens", "TrainingDivergedError", "psf_radius_px"]

log = logging.getLogger(__name__)

IGNORE = 255
# Bumped whenever the loop changes what it computes, so stale cache entries are not reused.
TRAINER_VERSION = 4  # 4: the utility net sees white-balanced sensor images


class TrainingDivergedError(RuntimeError):
    """A loss became NaN or Inf; the last good checkpoint is kept."""


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


class CoDesign:
    """One training run: a start spec, a scheme, a profile and a seed; cached by their hash."""

    def __init__(self, start: LensSpec, scheme: Scheme, profile: Any, seed: int, device: str, cache_dir: Path,
                 name: str | None = None, scene_set: str = "synthetic", replicas: SingleProcess | None = None,
                 use_shipped: bool = True):
        if scheme.optics and start.kind != "zernike":
            raise ValueError(f"scheme {scheme.name!r} trains the optics, but lens spec {start.name!r} is a {start.kind} "
                             "lens: it has no optical parameters to train (only a Zernike mask with mask.bounds_um "
                             "is co-designed)")
        if scheme.optics and not start.mask.trainable:
            raise ValueError(f"scheme {scheme.name!r} trains the optics, but lens spec {start.name!r} declares no "
                             "mask.bounds_um (a trainable mask declares its bounds)")
        self.start, self.scheme, self.profile, self.seed = start, scheme, profile, seed
        self.device, self.scene_set = device, scene_set
        # A trained mask starts from a seeded small draw; a fixed lens (scheme `fixed`) stays as it is.
        self.initial_um = initial_coefficients(start, seed) if scheme.optics else start.mask.zernike_um
        self.start_spec = dataclasses.replace(start, mask=dataclasses.replace(start.mask, zernike_um=self.initial_um))
        # Deliberately not in the config hash: a data-parallel run is the same run (same global
        # batches), so `lenses.load` finds it and either kind of run resumes the other's checkpoint.
        self.replicas = replicas or SingleProcess()
        self.name = name or scheme.name
        self.config = {
            "what": "codesign", "version": TRAINER_VERSION,
            "scheme": {"name": scheme.name, "optics": scheme.optics, "adversary": scheme.adversary,
                       "balance": settings(scheme.balance)},
            "start": start.to_dict(), "seed": seed, "scenes": scene_set,
            "clean_utility": clean_utility_id(profile, seed, scene_set),
            "initial_amplitude_um": INITIAL_AMPLITUDE_UM if scheme.optics else 0.0,
            "adversary": {"net": "RED10 skips residual", "margin_db": MARGIN_DB} if scheme.adversary else None,
            **_profile_fields(profile, _DATA_FIELDS + ("utility_model", "adversary_width", "pretrain_steps",
                                                       "codesign_steps", "optics_lr", "seg_lr", "deb_lr")
                              + scheme.balance.profile_fields),
        }
        root = Path(cache_dir) / "codesign"
        self.directory = root / f"{self.name}-{config_hash(self.config)}"
        self.checkpoint_path = root / f"{self.directory.name}.checkpoint.pt"
        self.live_dir = root / f"{self.directory.name}.live"  # curves while training (see `curves`)
        self.cache_dir = Path(cache_dir)
        # Install the package's copy of this very run (same folder name, so the same configuration)
        # when the cache has none (benchmark.codesign.shipped); False always trains.
        self.use_shipped = use_shipped

    # ---- loading -------------------------------------------------------------------------------
    def load(self) -> TrainedLens | None:
        """The finished run from the cache (installed first from the package's shipped copy of this run,
        if there is one and the cache has none: ``benchmark.codesign.shipped``), or None.

        Every file of the run folder is checked against its checksum; a run with a missing, corrupt
        or unreadable file is reported (each bad file with its path), removed and read as absent, so
        `load_or_train` trains it again rather than reuse a part of it.
        """
        d = self.directory
        if not d.is_dir() and not (self.use_shipped and install_shipped(d, self.config)):
            return None
        record = read_json(d / "record.json")
        spec_ok = verified(d / "lens.toml")
        utility = load_weights(d / "utility.safetensors", build_segformer(self.profile.utility_model))
        adversary = None
        if self.scheme.adversary:
            adversary = load_weights(d / "adversary.safetensors", build_adversary(self.profile.adversary_width))
        curves_ok = all([verified(d / name) for name in PUBLISHED_FILES])  # a list: check (and report) each
        if record is None or not spec_ok or utility is None or (self.scheme.adversary and adversary is None) \
                or not curves_ok:
            log.warning("co-design run %s is incomplete or corrupt (see above); removing it, it will be trained "
                        "again", d)
            shutil.rmtree(d, ignore_errors=True)
            return None
        lens = Lens(load_spec(d / "lens.toml"), geometry=None).to(self.device)
        if adversary is not None:
            adversary = adversary.to(self.device)
            adversary.eval()
        utility = utility.to(self.device)
        utility.eval()
        return TrainedLens(lens, utility, adversary, record, d)

    def load_or_train(self, progress: bool = True) -> TrainedLens:
        return self.load() or self.train(progress=progress)

    # ---- training ------------------------------------------------------------------------------
    def train(self, progress: bool = True, stop_after: int | None = None,
              on_step: Callable[[int, dict], None] | None = None) -> TrainedLens:
        """Train (resuming from the last checkpoint if one exists) and publish the artifacts.

        `stop_after` ends the call after that many steps of this call, leaving the checkpoint
        (used by tests to simulate an interruption). `on_step(step, stats)` sees every step's numbers.
        """
        t_start = time.perf_counter()
        progress = progress and self.replicas.is_writer
        state = self._setup(progress)
        self._restore(state)
        self.replicas.barrier()  # every replica has read the checkpoint before the writer may replace it
        done = self._loop(state, progress, stop_after, on_step)
        self._finish(state, time.perf_counter() - t_start, done)
        self.replicas.barrier()  # the others load what the writer published
        trained = self.load()
        assert trained is not None
        return trained

    def _setup(self, progress: bool) -> _State:
        """The starting lens, the networks (utility net from the clean one), their optimisers."""
        p, dev, rep = self.profile, self.device, self.replicas
        clean = rep.writer_first(lambda: clean_utility_net(p, self.seed, dev, self.cache_dir, self.scene_set, progress))
        sampler = CropSampler.from_split(self.scene_set, p.n_train, p.image_size, p.train_crop, p.batch_size, self.seed)
        torch.manual_seed(self.seed)
        lens = Lens(self.start_spec).to(dev)
        seg = build_segformer(p.utility_model).to(dev)
        seg.load_state_dict(clean.state_dict())
        deb, pretraining = None, None
        if self.scheme.adversary:
            deb, pretraining = rep.writer_first(lambda: pretrain_adversary(
                lens, sampler, p, self.seed, dev, self.cache_dir, self.scene_set, progress))
            deb = deb.to(dev)
        # A copy: `prepare` may load this run's data into it (the scheme's own stays a setting).
        balance = copy.copy(self.scheme.balance)
        opt_optics = None
        if self.scheme.optics:
            opt_optics = balance.optimizer([lens.coefficients_um], p.optics_lr)
            balance.prepare(self.cache_dir, p, self.seed, rep)
        return _State(lens=lens, seg=seg, deb=deb, seg_fit=rep.fitting(seg),
                      deb_fit=rep.fitting(deb) if deb is not None else None,
                      opt_seg=torch.optim.AdamW(seg.parameters(), lr=p.seg_lr),
                      opt_deb=torch.optim.Adam(deb.parameters(), lr=p.deb_lr) if deb is not None else None,
                      opt_optics=opt_optics, balance=balance, sampler=sampler, pretraining=pretraining)

    def _restore(self, state: _State) -> None:
        """Continue from the checkpoint of an interrupted run, if there is one."""
        ckpt = load_checkpoint(self.checkpoint_path)
        if ckpt is None:
            return
        state.step = int(ckpt["step"])
        with torch.no_grad():
            state.lens.coefficients_um.copy_(ckpt["coefficients_um"])
        for name in ("seg", "opt_seg", "deb", "opt_deb", "opt_optics"):
            target = getattr(state, name)
            if target is not None:
                target.load_state_dict(ckpt[name])
        state.curves = ckpt["curves"]
        log.info("%s: resuming from step %d (%s)", self.name, state.step, self.checkpoint_path)

    def _save_checkpoint(self, state: _State) -> None:
        ckpt: dict[str, Any] = {"step": state.step, "coefficients_um": state.lens.coefficients_um.detach().cpu(),
                                "curves": state.curves}
        for name in ("seg", "opt_seg", "deb", "opt_deb", "opt_optics"):
            target = getattr(state, name)
            if target is not None:
                ckpt[name] = target.state_dict()
        save_checkpoint(self.checkpoint_path, ckpt)

    def _loop(self, state: _State, progress: bool, stop_after: int | None,
              on_step: Callable[[int, dict], None] | None) -> int:
        """Run the remaining steps, checkpointing every tenth of the run; returns the steps run here."""
        p, rep = self.profile, self.replicas
        every = max(1, p.codesign_steps // 10)
        state.seg.train()
        if state.deb is not None:
            state.deb.train()
        bar = tqdm(range(state.step, p.codesign_steps), desc=f"co-design {self.name}", disable=not progress,
                   initial=state.step, total=p.codesign_steps, leave=False)
        state.log = CurveLog(self.live_dir, state.curves, enabled=rep.is_writer)
        done = 0
        try:
            for step in bar:
                stats = self._step(step, state)
                entry = {"step": step, **stats,
                         "coefficients_um": [float(c) for c in state.lens.coefficients_um.detach().cpu()]}
                state.curves.append(entry)
                state.log.write(entry)
                state.step = step + 1
                bar.set_postfix({k: f"{stats[k]:.3g}" for k in ("seg", "deb", "penalty", "bits") if k in stats})
                if on_step is not None:
                    on_step(step, stats)
                done += 1
                last = state.step == p.codesign_steps
                if rep.is_writer and (state.step % every == 0 or last):
                    self._save_checkpoint(state)
                if stop_after is not None and done >= stop_after and not last:
                    raise KeyboardInterrupt(f"stopped after {done} steps (checkpoint kept)")
        finally:
            state.log.close()
        return done

    def _step(self, step: int, state: _State) -> dict[str, float]:
        """One step on batch `step`. The networks' own training pass runs through `seg_fit`/`deb_fit`;
        the optics pass goes through the bare modules. Under data parallelism every loss here is this
        replica's estimate of the global-batch loss (see SingleProcess.scale)."""
        dev, rep = self.device, self.replicas
        seg, deb = state.seg, state.deb
        torch.manual_seed(self.seed * 7919 + step)  # drop-path etc.: reproducible across resumes
        x, y = state.sampler.batch(step, dev)
        rows = rep.rows(len(x))
        sensor = rep.sense(state.lens, x, rows, step_generator(self.seed, step, dev))
        w_seg, w_deb = rep.scale((y != IGNORE).sum()), rep.scale(x.numel())
        x, y = x[rows], y[rows]

        def seg_loss(net: torch.nn.Module, images: torch.Tensor) -> torch.Tensor:
            return F.cross_entropy(segment_logits(net, images), y, ignore_index=IGNORE, reduction=rep.reduction) * w_seg

        def deb_loss(net: torch.nn.Module, images: torch.Tensor) -> torch.Tensor:
            return F.mse_loss(net(images), x, reduction=rep.reduction) * w_deb

        # 1) the networks, on the detached sensor image (the utility net sees it white-balanced: the
        # camera's fixed ISP step, so the net is not asked to learn the sensor's tint)
        balanced = state.lens.white_balance(sensor)
        loss_seg = seg_loss(state.seg_fit, balanced.detach())
        stats = {"seg": rep.item(loss_seg.detach())}
        state.opt_seg.zero_grad(set_to_none=True)
        loss_seg.backward()
        state.opt_seg.step()
        if deb is not None:
            loss_deb = deb_loss(state.deb_fit, sensor.detach())  # type: ignore[arg-type]
            stats["deb"] = rep.item(loss_deb.detach())
            state.opt_deb.zero_grad(set_to_none=True)  # type: ignore[union-attr]
            loss_deb.backward()
            state.opt_deb.step()  # type: ignore[union-attr]
        self._guard(step, stats)
        # 2) the optics, through the updated networks
        if state.opt_optics is not None:
            ctx = OpticsContext(state.lens.coefficients_um, seg_loss(seg, balanced),
                                deb_loss(deb, sensor) if deb is not None else None, state.lens, rep)
            terms, optics_stats = state.balance.optics_terms(ctx)
            stats.update(optics_stats)
            self._guard(step, {"optics gradient": float(torch.stack(terms).sum(0).norm())})
            stats.update(state.balance.apply(state.opt_optics, terms, ctx))
            state.lens.clamp_to_bounds()
        stats["psf_radius_px"] = psf_radius_px(state.lens.psf())
        return stats

    def _guard(self, step: int, stats: dict[str, float]) -> None:
        bad = {k: v for k, v in stats.items() if not math.isfinite(v)}
        if bad:
            raise TrainingDivergedError(
                f"co-design {self.name!r} diverged at step {step}: {bad}; the last good checkpoint is kept at "
                f"{self.checkpoint_path if self.checkpoint_path.exists() else '(none yet)'}; lower the profile's "
                "optics_lr or seg_lr and rerun (it resumes from the checkpoint)")

    def _finish(self, state: _State, seconds: float, done: int) -> None:
        """The training record; the writer publishes the artifacts and drops the checkpoint."""
        lens, mask = state.lens, self.start_spec.mask
        final = [float(c) for c in lens.coefficients_um.detach().cpu()]
        record: dict[str, Any] = {
            "name": self.name, "scheme": self.scheme.name, "config": self.config, "curves": _columns(state.curves),
            "train_s": seconds, "seconds_per_step": seconds / done if done else None,
            "initial_coefficients_um": list(self.initial_um), "final_coefficients_um": final,
            "psf_radius_px": psf_radius_px(lens.psf()), "world_size": self.replicas.world}
        if mask.bounds_um is not None:
            limited = bound_limited(final, mask.bounds_um)
            record.update(bounds_um=[list(b) for b in mask.bounds_um], max_sag_um=mask.max_sag_um,
                          bound_limited=bool(limited), bound_limited_terms=[noll_name(j) for j in limited])
        if state.deb is not None:
            assert state.pretraining is not None
            record["adversary"] = {"pretraining": state.pretraining,
                                   "start": {k: v for k, v in state.pretraining["curve"][-1].items() if k != "step"},
                                   "end": Probe(state.sampler, self.seed, self.device).measure(lens, state.deb)}
        if self.replicas.is_writer:
            self._publish(state, record)
            discard(self.checkpoint_path)
            if state.log is not None:
                state.log.remove_live()

    def _publish(self, state: _State, record: dict) -> None:
        staging = self.directory.with_name(self.directory.name + f".staging-{torch.randint(1 << 30, (1,)).item()}")
        staging.mkdir(parents=True)
        start = ", ".join(f"{c:+.4f}" for c in self.initial_um)
        learned = dataclasses.replace(
            state.lens.current_spec(), name=self.name,
            description=f"co-designed with scheme {self.scheme.name!r}, seed {self.seed}, from initial coefficients "
                        f"[{start}] um (seeded draw of at most {INITIAL_AMPLITUDE_UM} um per free term)")
        write_verified(staging / "lens.toml", spec_to_toml(learned).encode())
        save_weights(staging / "utility.safetensors", state.seg)
        if state.deb is not None:
            save_weights(staging / "adversary.safetensors", state.deb)
        write_json(staging / "record.json", record)
        assert state.log is not None, "the loop opens the curve log"
        state.log.publish_into(staging, state.curves, f"{self.name}, seed {self.seed}: {self.scheme.description}")
        publish_directory(staging, self.directory)


@dataclass
class _State:
    """Everything a run carries from step to step (what a checkpoint saves, and the rest)."""

    lens: Lens
    seg: torch.nn.Module
    deb: torch.nn.Module | None
    seg_fit: torch.nn.Module                 # what the networks' own training pass calls (DDP wrapper)
    deb_fit: torch.nn.Module | None
    opt_seg: torch.optim.Optimizer
    opt_deb: torch.optim.Optimizer | None
    opt_optics: torch.optim.Optimizer | None
    balance: Balance
    sampler: CropSampler
    pretraining: dict[str, Any] | None       # the adversary's pre-training record
    step: int = 0                            # the next step to run
    curves: list[dict[str, Any]] = field(default_factory=list)   # one entry per step run
    log: CurveLog | None = None


def _columns(rows: list[dict[str, Any]]) -> dict[str, list]:
    """Per-step entries -> one list per quantity (NaN where a step did not log it)."""
    keys = list(dict.fromkeys(k for row in rows for k in row))
    return {k: [row.get(k, math.nan) for row in rows] for k in keys}
