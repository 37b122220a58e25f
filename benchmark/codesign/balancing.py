"""How the optics step weighs utility against privacy: one small class per balancing method.

Every method answers one question per step through the same interface:

    terms, stats = balance.optics_terms(ctx)      # gradients (6,) of each term w.r.t. the mask
    stats |= balance.apply(optimizer, terms, ctx)  # one optimiser step on the coefficients

`terms` are the global-batch gradients of the terms of the optics objective (under data
parallelism every replica's estimate is averaged first), `stats` the numbers the run logs per
step: every gradient norm, the penalty and the lambda actually applied. Plain Adam steps on the
sum of the terms; MTAdam balances them one against the other.

Each class is a frozen dataclass, so a scheme's settings enter the run's config hash as they are.
"""

from __future__ import annotations

import dataclasses
from abc import ABC, abstractmethod
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING, Any

import torch

from benchmark.codesign.mtadam import MTAdam
from lenses.bound import fano_ceiling, noise_to_signal, plate_bits
from lenses.lens import Lens

if TYPE_CHECKING:  # the replicas interface lives with the loop
    from benchmark.codesign.replicas import SingleProcess


@dataclass
class OpticsContext:
    """What one optics step sees.

    Attributes:
        coefficients: the leaf tensor the step updates (the lens's `coefficients_um`, (6,)).
        utility_loss: L_seg (scalar) through the updated utility net, differentiable w.r.t.
            `coefficients`; this replica's estimate of the global-batch loss.
        adversary_loss: L_deb (scalar) through the updated adversary, or None without one.
        lens: the lens being trained (the information bound reads its PSF and sensor).
        replicas: how the batch is spread over processes (`trainer.SingleProcess` or
            `distributed.DataParallel`).
    """

    coefficients: torch.Tensor
    utility_loss: torch.Tensor
    adversary_loss: torch.Tensor | None
    lens: Lens
    replicas: SingleProcess

    def gradient(self, loss: torch.Tensor, create_graph: bool = False) -> torch.Tensor:
        """This replica's gradient of `loss` w.r.t. the coefficients (graphs kept for the other terms)."""
        (g,) = torch.autograd.grad(loss, self.coefficients, retain_graph=True, create_graph=create_graph)
        return g

    def mean_gradient(self, loss: torch.Tensor) -> torch.Tensor:
        """The global-batch gradient of `loss` w.r.t. the coefficients (no graph)."""
        return self.replicas.mean(self.gradient(loss))


def _norm(g: torch.Tensor) -> float:
    return float(g.detach().norm())


class Balance(ABC):
    """A balancing method: which terms step the optics and how they are combined."""

    #: profile fields the method reads (they enter the run's config hash)
    profile_fields: tuple[str, ...] = ()

    def optimizer(self, params: list[torch.Tensor], lr: float) -> torch.optim.Optimizer:
        """The optimiser of the mask coefficients."""
        return torch.optim.Adam(params, lr=lr)

    def prepare(self, cache_dir: Path, profile: Any, seed: int, replicas: SingleProcess) -> None:
        """Load what the method needs before the first step (cached data); nothing by default."""

    @abstractmethod
    def optics_terms(self, ctx: OpticsContext) -> tuple[list[torch.Tensor], dict[str, float]]:
        """Global-batch gradients (each shaped like the coefficients) of the objective's terms, and stats."""

    def apply(self, optimizer: torch.optim.Optimizer, terms: list[torch.Tensor],
              ctx: OpticsContext) -> dict[str, float]:
        """One step on the sum of the terms; returns stats known only after the step (none here)."""
        optimizer.zero_grad(set_to_none=True)
        ctx.coefficients.grad = torch.stack(terms).sum(0)
        optimizer.step()
        return {}


@dataclass(frozen=True)
class FixedLambda(Balance):
    """lambda_seg L_seg - lambda_deb L_deb with fixed weights (paper eq. 3); L_seg alone without adversary."""

    lambda_deb: float = 0.0
    lambda_seg: float = 1.0

    def optics_terms(self, ctx: OpticsContext) -> tuple[list[torch.Tensor], dict[str, float]]:
        g_seg = ctx.mean_gradient(ctx.utility_loss)
        terms, stats = [self.lambda_seg * g_seg], {"grad_seg_norm": _norm(g_seg)}
        if ctx.adversary_loss is not None:
            g_deb = ctx.mean_gradient(ctx.adversary_loss)
            terms.append(-self.lambda_deb * g_deb)
            stats.update(grad_deb_norm=_norm(g_deb), lambda_deb=self.lambda_deb)
        return terms, stats


@dataclass(frozen=True)
class MTAdamBalance(Balance):
    """L_seg and -lambda_deb L_deb balanced by MTAdam: the adversary's gradient is rescaled to the
    running norm of the utility's (the anchor) before Adam sees it."""

    lambda_deb: float = 1.0
    lambda_seg: float = 1.0

    def optimizer(self, params: list[torch.Tensor], lr: float) -> torch.optim.Optimizer:
        return MTAdam(params, lr=lr)

    def optics_terms(self, ctx: OpticsContext) -> tuple[list[torch.Tensor], dict[str, float]]:
        if ctx.adversary_loss is None:
            raise ValueError("MTAdam balancing needs an adversary (scheme.adversary = True)")
        g_seg, g_deb = ctx.mean_gradient(ctx.utility_loss), ctx.mean_gradient(ctx.adversary_loss)
        return [self.lambda_seg * g_seg, -self.lambda_deb * g_deb], {"grad_seg_norm": _norm(g_seg),
                                                                      "grad_deb_norm": _norm(g_deb)}

    def apply(self, optimizer: torch.optim.Optimizer, terms: list[torch.Tensor],
              ctx: OpticsContext) -> dict[str, float]:
        assert isinstance(optimizer, MTAdam)
        optimizer.step_gradients([[g] for g in terms])
        # The weight MTAdam actually gave L_deb this step: lambda_deb times its rescaling to the anchor.
        running = optimizer.state[ctx.coefficients]["grad_norm"]
        return {"lambda_deb": self.lambda_deb * float(running[0] / running[1].clamp_min(1e-30))}


@dataclass(frozen=True)
class GradientPenalty(Balance):
    """lambda_seg L_seg - lambda_deb L_deb + P, the gradient penalty of the paper's eq. 4.

    Literal (`scale_free=False`, lens `gp-literal`): P = (||dL_deb/dtheta||_2 - 1)^2, eq. 4 as
    printed. Its value depends on the unit of theta: with theta in um the gradient is about 2e-4,
    P sits at 0.9996 all run and pulls on the optics 10 to 40 times less than L_seg, so `gp`
    trained like `os`; in nm the same mask gives 2e-7. No unit makes "1" mean anything by itself.

    Scale-free (default, lens `gp`): P = (||dL_deb/dtheta|| / sg(||dL_seg/dtheta||) - 1)^2, with
    sg() a stop-gradient. Both norms scale alike with the unit of theta, so P, and with it every
    optics step, is the same in um, nm or waves (tested). It keeps the paper's reading of the
    penalty, "force the adversary's gradient norm to 1 so it cannot vanish", with the unit made
    explicit: 1 is the utility's own pull on the optics. The penalty pushes the mask to where the
    adversary's gradient is as strong as the utility's, so the privacy term keeps a say in every
    step however fast the adversary converges. Stopping the gradient through the utility norm
    keeps P from rewarding a weaker utility gradient.

    `lambda_deb` (1 for `gp`, as for the literal form): with the scale-free penalty the balance is
    set by P, so the plain adversarial term needs no tuned weight; 1 keeps eq. 4's form.
    """

    lambda_deb: float = 1.0
    lambda_seg: float = 1.0
    scale_free: bool = True

    def optics_terms(self, ctx: OpticsContext) -> tuple[list[torch.Tensor], dict[str, float]]:
        if ctx.adversary_loss is None:
            raise ValueError("the gradient penalty needs an adversary (scheme.adversary = True)")
        g_seg = ctx.mean_gradient(ctx.utility_loss)
        g_deb_local = ctx.gradient(ctx.adversary_loss, create_graph=True)
        reference = g_seg.norm().clamp_min(1e-30) if self.scale_free else torch.ones((), device=g_seg.device)
        penalty, term = ctx.replicas.gradient_penalty(g_deb_local, reference)
        g_pen = ctx.replicas.mean(ctx.gradient(term))
        g_deb = ctx.replicas.mean(g_deb_local.detach())
        stats = {"grad_seg_norm": _norm(g_seg), "grad_deb_norm": _norm(g_deb), "penalty": float(penalty),
                 "grad_penalty_norm": _norm(g_pen), "lambda_deb": self.lambda_deb,
                 "gradient_ratio": _norm(g_deb) / float(reference)}
        return [self.lambda_seg * g_seg, -self.lambda_deb * g_deb, g_pen], stats


@dataclass(frozen=True)
class InformationBound(Balance):
    """lambda_seg L_seg + lambda_info relu((B(w) + 1) / H_plate - eps): the attack-independent bound
    (lenses/bound.py) instead of an adversary. B is the bits a plate `width_px` wide leaks and
    (B + 1) / H_plate its Fano ceiling, left unclipped so that its gradient never vanishes."""

    lambda_info: float = 0.01
    width_px: int = 32          # plate width the bound term protects: the median plate of the scenes
    eps: float = 0.05           # target ceiling on any attacker's exact-read rate
    lambda_seg: float = 1.0
    profile_fields = ("bound_scenes",)

    def prepare(self, cache_dir: Path, profile: Any, seed: int, replicas: SingleProcess) -> None:
        from benchmark.scenes.plate_spectrum import cached_plate_spectrum
        from benchmark.scenes import plate_entropy_bits
        spectrum = replicas.writer_first(lambda: cached_plate_spectrum(cache_dir, profile.bound_scenes, seed=seed))
        # Frozen dataclass: the loaded data is state of this run, not a setting.
        object.__setattr__(self, "_spectrum", spectrum)
        object.__setattr__(self, "_entropy_bits", plate_entropy_bits())

    def optics_terms(self, ctx: OpticsContext) -> tuple[list[torch.Tensor], dict[str, float]]:
        spectrum, entropy_bits = self._spectrum, self._entropy_bits  # type: ignore[attr-defined]
        g_seg = ctx.mean_gradient(ctx.utility_loss)
        nsr = noise_to_signal(ctx.lens, spectrum.mean_radiance)
        bits = plate_bits(ctx.lens.psf().cpu(), spectrum, self.width_px, nsr)  # the bound runs on the CPU; .cpu() keeps the gradient
        ceiling = (bits + 1.0) / entropy_bits
        g_bound = ctx.gradient(torch.relu(ceiling - self.eps))  # the bound is the same on every replica
        stats = {"grad_seg_norm": _norm(g_seg), "grad_bound_norm": _norm(g_bound), "bits": float(bits.detach()),
                 "ceiling": float(fano_ceiling(float(bits.detach()), entropy_bits)), "lambda_info": self.lambda_info}
        return [self.lambda_seg * g_seg, self.lambda_info * g_bound], stats


def settings(balance: Balance) -> dict[str, Any]:
    """The method and its settings, for the config hash and the training record."""
    return {"method": type(balance).__name__, **dataclasses.asdict(balance)}  # type: ignore[call-overload]
