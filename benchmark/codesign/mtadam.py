"""MTAdam: Adam that balances several loss terms (Malkiel & Wolf 2020, arXiv:2006.14683).

Used by the ``os-d-mtadam`` co-design scheme to balance L_seg against -L_deb on the optics.

For every parameter tensor p and every loss term i at step t:

    g_i   = dL_i/dp
    n_i   = ||g_i||                                   (t = 1)
    n_i   = beta3 n_i + (1 - beta3) ||g_i||           (t > 1)
    g_i  <- rank_i * n_a / n_i * g_i                  if n_i > 1e-10, where a is the first term
                                                      with n_a > 1e-10 (normally term 0)
    m_i   = beta1 m_i + (1 - beta1) g_i
    v_i   = beta2 v_i + (1 - beta2) g_i^2
    d_i   = sqrt(v_i) / sqrt(1 - beta2^t) + eps
    p    <- p - lr / (1 - beta1^t) * sum_i m_i / max_i d_i      (max is elementwise)

so every term's gradient is brought to the anchor term's running magnitude before Adam sees
it, and the shared denominator (the largest second moment of any term) keeps the per-element
step at most about lr per term.

Deviations from the official code (github.com/ItzikMalkiel/MTAdam, ``mtadam.py``), none of
which changes the update above:

- Gradients come from ``torch.autograd.grad`` rather than ``loss.backward()``: ``p.grad`` of
  these and any other parameters is left untouched, so this optimizer can step the optics
  while other optimizers own the networks sharing the graph.
- Running norms live in ``self.state`` (saved by ``state_dict``) on the parameter's device,
  not as attributes on the parameter tensor created with a hard-coded ``.cuda()``.
- A term that does not reach a parameter gives it a zero gradient (the official loop
  ``break``s out of the group instead); a parameter that no term reaches is skipped.
- ``ranks`` defaults to all ones; ``weight_decay``, ``amsgrad`` and ``closure`` are omitted
  (the co-design uses none of them); the number of terms is fixed after the first step.
"""

from __future__ import annotations

import math
from collections.abc import Iterable, Sequence
from typing import Any

import torch

__all__ = ["MTAdam"]

# Below this running norm a term is treated as absent for that tensor (official threshold).
_NORM_FLOOR = 1e-10


class MTAdam(torch.optim.Optimizer):
    """Multi-term Adam.

    Args:
        params: parameters or parameter groups, as for ``torch.optim.Adam``.
        lr: learning rate (per-element step size is about ``lr`` per term).
        betas: (beta1, beta2, beta3): EMA coefficients of the first moment, the second moment
            and the per-term gradient norms.
        eps: added to the denominator for numerical stability.

    Call ``step(losses, ranks)`` instead of ``loss.backward(); step()``: it differentiates
    each term itself.
    """

    def __init__(
        self,
        params: Iterable[torch.Tensor] | Iterable[dict[str, Any]],
        lr: float = 1e-3,
        betas: tuple[float, float, float] = (0.9, 0.999, 0.9),
        eps: float = 1e-8,
    ) -> None:
        if lr < 0.0:
            raise ValueError(f"MTAdam lr must be >= 0, got {lr}")
        if eps < 0.0:
            raise ValueError(f"MTAdam eps must be >= 0, got {eps}")
        if len(betas) != 3 or not all(0.0 <= b < 1.0 for b in betas):
            raise ValueError(f"MTAdam betas must be three values in [0, 1) (beta1, beta2, beta3), got {betas}")
        super().__init__(params, dict(lr=lr, betas=tuple(betas), eps=eps))

    def step(  # type: ignore[override]
        self, losses: Sequence[torch.Tensor], ranks: Sequence[float] | None = None
    ) -> None:
        """Differentiate each loss term and take one balanced Adam step.

        Args:
            losses: scalar loss tensors, anchor term first (every other term is rescaled to the
                anchor's running gradient magnitude). Their graphs are freed afterwards, as by
                ``backward()``.
            ranks: relative weight of each term after balancing (default: all 1).

        Raises:
            ValueError: no losses, a non-scalar loss, ``ranks`` of the wrong length, or a
                number of terms different from the previous steps.
        """
        if len(losses) == 0:
            raise ValueError("MTAdam.step needs at least one loss term")
        if any(loss.numel() != 1 for loss in losses):
            raise ValueError(f"MTAdam losses must be scalars, got shapes {[tuple(loss.shape) for loss in losses]}")
        self._check_ranks(len(losses), ranks)
        params = [p for group in self.param_groups for p in group["params"] if p.requires_grad]
        self.step_gradients(self._term_gradients(losses, params), ranks)

    def step_gradients(self, per_term: Sequence[Sequence[torch.Tensor | None]],
                       ranks: Sequence[float] | None = None) -> None:
        """The step of ``step`` from gradients already taken: ``per_term[i][k]`` is term i's
        gradient of the k-th trainable parameter (in parameter-group order), None where the term
        does not reach it. For callers that differentiate the terms themselves (the co-design
        averages each term's gradient over data-parallel ranks first)."""
        n_terms = len(per_term)
        if n_terms == 0:
            raise ValueError("MTAdam.step needs at least one loss term")
        ranks = self._check_ranks(n_terms, ranks)
        pairs = [(p, group) for group in self.param_groups for p in group["params"] if p.requires_grad]
        if any(len(term) != len(pairs) for term in per_term):
            raise ValueError(f"MTAdam.step_gradients needs one gradient (or None) per trainable parameter "
                             f"({len(pairs)}) for every term, got {[len(t) for t in per_term]}")
        with torch.no_grad():
            for k, (p, group) in enumerate(pairs):
                grads = [term[k] for term in per_term]
                if all(g is None for g in grads):
                    continue
                stacked = torch.stack([torch.zeros_like(p) if g is None else g for g in grads])
                self._update(p, stacked, ranks, group)

    @staticmethod
    def _check_ranks(n_terms: int, ranks: Sequence[float] | None) -> list[float]:
        ranks = [1.0] * n_terms if ranks is None else list(ranks)
        if len(ranks) != n_terms:
            raise ValueError(f"MTAdam got {n_terms} losses but {len(ranks)} ranks; give one rank per loss")
        return ranks

    @staticmethod
    def _term_gradients(
        losses: Sequence[torch.Tensor], params: list[torch.Tensor]
    ) -> list[Sequence[torch.Tensor | None]]:
        grads: list[Sequence[torch.Tensor | None]] = []
        with torch.enable_grad():
            for i, loss in enumerate(losses):
                if not loss.requires_grad:
                    grads.append([None] * len(params))
                    continue
                # Terms usually share one forward graph: keep it until the last term is done.
                grads.append(
                    torch.autograd.grad(loss, params, retain_graph=i < len(losses) - 1, allow_unused=True)
                )
        return grads

    def _update(self, p: torch.Tensor, grads: torch.Tensor, ranks: list[float], group: dict[str, Any]) -> None:
        """One MTAdam update of parameter ``p`` from its per-term gradients ``grads`` (T, *p.shape)."""
        n_terms = grads.shape[0]
        beta1, beta2, beta3 = group["betas"]
        state = self.state[p]
        if not state:
            state["step"] = 0
            state["grad_norm"] = torch.zeros(n_terms, dtype=p.dtype, device=p.device)
            state["exp_avg"] = torch.zeros_like(grads)
            state["exp_avg_sq"] = torch.zeros_like(grads)
        elif state["exp_avg"].shape[0] != n_terms:
            raise ValueError(
                f"MTAdam was stepped with {state['exp_avg'].shape[0]} loss terms before and {n_terms} now; "
                "the number of terms must stay the same"
            )
        state["step"] += 1
        step = state["step"]

        norms = grads.flatten(1).norm(dim=1)
        if step == 1:
            state["grad_norm"].copy_(norms)
        else:
            state["grad_norm"].mul_(beta3).add_(norms, alpha=1 - beta3)
        running = state["grad_norm"]

        # Anchor: the first term with a usable running norm (argmax returns the first maximum),
        # computed on the device so that no host sync is needed.
        usable = running > _NORM_FLOOR
        anchor_norm = running[usable.to(torch.uint8).argmax()]
        rank_t = torch.tensor(ranks, dtype=p.dtype, device=p.device)
        scale = torch.where(usable, rank_t * anchor_norm / running.clamp_min(_NORM_FLOOR), torch.ones_like(running))
        grads = grads * scale.view(-1, *([1] * p.dim()))

        exp_avg, exp_avg_sq = state["exp_avg"], state["exp_avg_sq"]
        exp_avg.mul_(beta1).add_(grads, alpha=1 - beta1)
        exp_avg_sq.mul_(beta2).addcmul_(grads, grads, value=1 - beta2)
        bias_correction1 = 1 - beta1**step
        bias_correction2 = 1 - beta2**step
        denom = (exp_avg_sq.sqrt() / math.sqrt(bias_correction2)).add_(group["eps"]).amax(dim=0)
        p.sub_(exp_avg.sum(dim=0) / denom, alpha=group["lr"] / bias_correction1)
