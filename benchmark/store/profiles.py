"""Run profiles: every size, count and step budget in one place, printed with the results.

A profile's description gives what a run of it measured (`benchmark.store.measured_costs`, from
docs/costs.md), generated, never typed in; it is prose, not a setting, so it is left out of
`Profile.to_dict` (the settings that key cached results and leaderboard entries).
"""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass
from typing import TYPE_CHECKING

from benchmark.store.measured_costs import run_text
from common.plugins import suggest

if TYPE_CHECKING:
    from attacks.base import AttackBudget


@dataclass(frozen=True)
class Profile:
    name: str
    description: str
    # Scenes
    image_size: tuple[int, int]   # (H, W) of evaluation scenes
    n_val: int                    # evaluation scenes per seed
    n_train: int                  # training scenes (co-design, attackers that fit)
    train_crop: tuple[int, int]   # (h, w) random crops for training
    batch_size: int
    # Co-design (benchmark/codesign)
    utility_model: str            # SegFormer variant (benchmark.codesign.utility.segformer)
    adversary_width: int          # RED10 width
    pretrain_steps: int           # clean utility pre-training, shared by all lenses (benchmark.codesign.utility.pretrain)
    pretrain_scenes: int          # distinct training scenes of the clean pre-training
    pretrain_crop: tuple[int, int]  # (h, w) crops of the clean pre-training
    pretrain_batch: int           # crops per step of the clean pre-training
    pretrain_lr: float            # peak AdamW learning rate (linear warmup, then cosine to 1 % of it)
    pretrain_warmup: int          # warmup steps
    pretrain_eval_every: int      # steps between learning-curve points (sharp val mIoU)
    codesign_steps: int           # co-design steps per lens
    optics_lr: float              # Adam on the Zernike coefficients (um)
    seg_lr: float                 # AdamW on the utility net
    deb_lr: float                 # Adam on the RED10 adversary
    # Privacy bound (lenses/bound.py)
    bound_scenes: int             # training scenes whose plates give the plate spectrum
    # Trained restorers (attacks/)
    # Optimiser steps of each trained attacker. quick: 200, where the known-pairs NAFNet's held-out
    # PSNR flattens (leaderboard/studies/nafnet_known_pairs_steps.json: the last 20 % of steps add
    # < 0.2 dB; 400 steps buy 0.28 dB more for twice the fit time).
    restorer_steps: int
    nafnet_width: int
    nafnet_enc_blocks: tuple[int, ...]
    nafnet_middle_blocks: int
    nafnet_dec_blocks: tuple[int, ...]
    # Plate set (benchmark.runner.tasks.plate_set): with a quota, plates are read on windows around
    # their vehicles (benchmark.scenes.windows), cut from val frames drawn in order until every width
    # bin from 8 to 64 px holds `plates_per_width_bin` scored plates or `plate_frames` frames are drawn;
    # wider bins take up to `plates_per_wide_bin` from those frames (their windows are 2-3x larger).
    plates_per_width_bin: int = 0  # per seed; 0: read plates on the n_val scenes themselves
    plates_per_wide_bin: int = 0
    plate_frames: int = 0          # the most val frames drawn for the plate set

    def to_dict(self) -> dict:
        """The settings (every field but the description)."""
        d = dataclasses.asdict(self)
        d.pop("description")
        return d

    def attack_budget(self) -> AttackBudget:
        """What this profile lets an attacker spend on its fit (``attacks.AttackBudget``): the profile's
        name and its trained-restorer fields, the training crop the smaller side of ``train_crop`` made
        even (the Bayer phase)."""
        from attacks.base import AttackBudget  # lazy: the CLI's parser imports profiles and no torch

        crop = min(self.train_crop)
        return AttackBudget(profile=self.name, restorer_steps=self.restorer_steps, nafnet_width=self.nafnet_width,
                            nafnet_enc_blocks=tuple(self.nafnet_enc_blocks),
                            nafnet_middle_blocks=self.nafnet_middle_blocks,
                            nafnet_dec_blocks=tuple(self.nafnet_dec_blocks), crop_px=crop - crop % 2,
                            batch_size=self.batch_size, max_train_images=self.n_train)


def _measured(purpose: str, profile: str) -> str:
    """`purpose`, then what a run of `profile` measured (docs/costs.md via measured_costs), if any."""
    measured = run_text(profile)
    return f"{purpose}; measured: {measured}" if measured else purpose


PROFILES: dict[str, Profile] = {
    p.name: p
    for p in (
        Profile("smoke", _measured("for tests and a first look", "smoke"),
                image_size=(128, 256), n_val=4, n_train=8, train_crop=(64, 64), batch_size=4,
                utility_model="tiny", adversary_width=8, pretrain_steps=4, codesign_steps=4,
                pretrain_scenes=8, pretrain_crop=(64, 64), pretrain_batch=4, pretrain_lr=6e-4, pretrain_warmup=1,
                pretrain_eval_every=4,
                optics_lr=2e-2, seg_lr=6e-4, deb_lr=1e-3, bound_scenes=30,
                restorer_steps=40, nafnet_width=8, nafnet_enc_blocks=(1, 1), nafnet_middle_blocks=1,
                nafnet_dec_blocks=(1, 1), plates_per_width_bin=1, plates_per_wide_bin=1,
                plate_frames=4),
        Profile("quick", _measured("the CPU default", "quick"),
                image_size=(512, 1024), n_val=64, n_train=64, train_crop=(128, 128), batch_size=8,
                utility_model="b0", adversary_width=32, pretrain_steps=1800, codesign_steps=200,
                pretrain_scenes=256, pretrain_crop=(128, 128), pretrain_batch=8, pretrain_lr=1e-3,
                pretrain_warmup=90, pretrain_eval_every=180,
                optics_lr=2e-2, seg_lr=6e-4, deb_lr=1e-3, bound_scenes=300,
                restorer_steps=200, nafnet_width=16, nafnet_enc_blocks=(1, 1, 2), nafnet_middle_blocks=2,
                nafnet_dec_blocks=(1, 1, 1), plates_per_width_bin=50,
                plates_per_wide_bin=25, plate_frames=1000),
        Profile("paper", "the paper's settings, for a GPU: full-size scenes, 512x512 crops, batch 16, 200 epochs",
                image_size=(1024, 2048), n_val=500, n_train=2975, train_crop=(512, 512), batch_size=16,
                utility_model="b0", adversary_width=64, pretrain_steps=40000, codesign_steps=200 * 186,
                pretrain_scenes=2975, pretrain_crop=(512, 512), pretrain_batch=16, pretrain_lr=6e-4,
                pretrain_warmup=1500, pretrain_eval_every=2000,
                optics_lr=1e-3, seg_lr=6e-5, deb_lr=1e-3, bound_scenes=300,
                restorer_steps=100000, nafnet_width=32, nafnet_enc_blocks=(1, 1, 1, 28), nafnet_middle_blocks=1,
                nafnet_dec_blocks=(1, 1, 1, 1)),
    )
}


def get_profile(name: str) -> Profile:
    """The profile called `name`; unknown names fail with the valid ones."""
    try:
        return PROFILES[name]
    except KeyError:
        raise ValueError(f"unknown profile {name!r}; valid: {', '.join(PROFILES)}.{suggest(name, PROFILES)}") from None
