"""What the runner hands an attacker (benchmark.runner.tasks.fit_context): the typed fields of
attacks.FitContext, filled from the run's configuration and lens."""

from __future__ import annotations

import attacks
import lenses
from attacks.networks import RED10
from benchmark.runner.config import RunConfig
from benchmark.runner.tasks import fit_context
from benchmark.scenes import PLATE_FORMAT
from benchmark.store.profiles import get_profile


def config(tmp_path, **fields) -> RunConfig:
    return RunConfig(lenses=["defocus"], attacks=None, scenes="synthetic", profile=get_profile("smoke"), seeds=[0],
                     cache_dir=tmp_path, **fields)


def test_the_context_carries_the_runs_budget_format_segmenter_and_the_lenss_adversary(tmp_path):
    lens = lenses.load("defocus")
    ctx = fit_context(lens, config(tmp_path), 3, segment=None)
    assert ctx.budget == get_profile("smoke").attack_budget() and ctx.budget.profile == "smoke"
    assert ctx.plate_format == PLATE_FORMAT and ctx.seed == 3 and ctx.segmenter is None and ctx.adversary is None
    assert ctx.train_pairs is not None and ctx.lens is lens

    def segment(images):
        return images[:, 0].long()

    object.__setattr__(lens, "adversary", RED10(width=4))
    ctx = fit_context(lens, config(tmp_path, plate_format="LLLLLLLLLL"), 0, segment=segment)
    assert ctx.plate_format == "LLLLLLLLLL"  # the format the run names reaches the readers, not only the bound
    assert ctx.segmenter is segment and ctx.adversary is lens.adversary


def test_the_sharp_scenes_get_no_lens_no_pairs_and_no_adversary(tmp_path):
    ctx = fit_context(None, config(tmp_path), 0, segment=None)
    assert ctx.lens is None and ctx.train_pairs is None and ctx.adversary is None
    assert isinstance(ctx.budget, attacks.AttackBudget)
