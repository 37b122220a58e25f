"""MTAdam against hand-computed steps, its balancing property, and state round trips."""

import io
import math

import pytest
import torch

from benchmark.codesign.mtadam import MTAdam

A = torch.tensor([1.0, -2.0, 0.5], dtype=torch.float64)
B = torch.tensor([3.0, 0.0, -1.0], dtype=torch.float64)


def _toy(w: torch.Tensor, u: torch.Tensor) -> list[torch.Tensor]:
    """Two terms: L0 reaches w and u, L1 only w (so u's second term is absent)."""
    l0 = ((w - A) ** 2).sum() + 3 * (u**2).sum()
    l1 = 100 * (w * B).sum()
    return [l0, l1]


def _params() -> tuple[torch.Tensor, torch.Tensor]:
    w = torch.tensor([0.2, 0.4, -0.3], dtype=torch.float64, requires_grad=True)
    u = torch.tensor([1.0, -0.5], dtype=torch.float64, requires_grad=True)
    return w, u


def test_first_two_steps_match_hand_computation() -> None:
    lr, (b1, b2, b3), eps, ranks = 0.01, (0.9, 0.999, 0.9), 1e-8, (1.0, 0.5)
    w, u = _params()
    w0, u0 = w.detach().clone(), u.detach().clone()
    opt = MTAdam([w, u], lr=lr, betas=(b1, b2, b3), eps=eps)
    opt.step(_toy(w, u), ranks)
    w1, u1 = w.detach().clone(), u.detach().clone()
    opt.step(_toy(w, u), ranks)

    # Step 1 on w: raw gradients g0 = 2 (w - A), g1 = 100 B; norms n_i = ||g_i||.
    g0, g1 = 2 * (w0 - A), 100 * B
    n0, n1 = g0.norm(), g1.norm()
    s0, s1 = ranks[0] * g0, ranks[1] * n0 / n1 * g1
    m0, m1 = (1 - b1) * s0, (1 - b1) * s1
    v0, v1 = (1 - b2) * s0**2, (1 - b2) * s1**2
    d = torch.maximum(v0.sqrt() / math.sqrt(1 - b2) + eps, v1.sqrt() / math.sqrt(1 - b2) + eps)
    w1_expected = w0 - lr / (1 - b1) * (m0 + m1) / d
    torch.testing.assert_close(w1, w1_expected, rtol=1e-12, atol=1e-12)

    # Step 1 on u: only L0 reaches it; term 1's gradient is zero and stays unscaled.
    gu = 6 * u0
    mu, vu = (1 - b1) * ranks[0] * gu, (1 - b2) * (ranks[0] * gu) ** 2
    du = torch.maximum(vu.sqrt() / math.sqrt(1 - b2) + eps, torch.full_like(gu, eps))
    u1_expected = u0 - lr / (1 - b1) * mu / du
    torch.testing.assert_close(u1, u1_expected, rtol=1e-12, atol=1e-12)

    # Step 2 on w: running norms are EMAs with beta3, moments accumulate.
    g0b, g1b = 2 * (w1 - A), 100 * B
    n0b = b3 * n0 + (1 - b3) * g0b.norm()
    n1b = b3 * n1 + (1 - b3) * g1b.norm()
    s0b, s1b = ranks[0] * g0b, ranks[1] * n0b / n1b * g1b
    m0b, m1b = b1 * m0 + (1 - b1) * s0b, b1 * m1 + (1 - b1) * s1b
    v0b, v1b = b2 * v0 + (1 - b2) * s0b**2, b2 * v1 + (1 - b2) * s1b**2
    c2 = math.sqrt(1 - b2**2)
    db = torch.maximum(v0b.sqrt() / c2 + eps, v1b.sqrt() / c2 + eps)
    w2_expected = w1 - lr / (1 - b1**2) * (m0b + m1b) / db
    torch.testing.assert_close(w.detach(), w2_expected, rtol=1e-12, atol=1e-12)


def test_small_term_is_not_drowned() -> None:
    # L0 pulls w to a, L1 (1000x weaker) pulls it to b. Adam on the sum lands on L0's optimum;
    # MTAdam gives both terms the same gradient magnitude, so L1 moves w as much as L0 does.
    a = torch.tensor([1.0, 0.0])
    b = torch.tensor([0.0, 1.0])

    def losses(w: torch.Tensor) -> list[torch.Tensor]:
        return [1000 * ((w - a) ** 2).sum(), ((w - b) ** 2).sum()]

    w_adam = torch.zeros(2, requires_grad=True)
    w_mt = torch.zeros(2, requires_grad=True)
    adam = torch.optim.Adam([w_adam], lr=1e-2)
    mtadam = MTAdam([w_mt], lr=1e-2)
    for _ in range(300):
        adam.zero_grad()
        sum(losses(w_adam)).backward()
        adam.step()
        mtadam.step(losses(w_mt))
    assert w_adam[1] < 0.01  # the weak term is drowned
    assert w_mt[1] > 0.3 and w_mt[0] > 0.3  # both terms moved w


def test_parameter_grads_are_left_untouched() -> None:
    w, u = _params()
    MTAdam([w, u]).step(_toy(w, u))
    assert w.grad is None and u.grad is None


def test_state_dict_round_trip() -> None:
    w, u = _params()
    opt = MTAdam([w, u], lr=0.05)
    for _ in range(3):
        opt.step(_toy(w, u))
    # Through bytes, as a checkpoint would: state_dict() returns live references to the state.
    buffer = io.BytesIO()
    torch.save(opt.state_dict(), buffer)
    buffer.seek(0)
    saved = torch.load(buffer, weights_only=True)

    w2, u2 = w.detach().clone().requires_grad_(), u.detach().clone().requires_grad_()
    opt2 = MTAdam([w2, u2], lr=0.05)
    opt2.load_state_dict(saved)
    for _ in range(2):
        opt.step(_toy(w, u))
        opt2.step(_toy(w2, u2))
    assert torch.equal(w, w2) and torch.equal(u, u2)
    assert opt2.state[w2]["step"] == 5


def test_changing_number_of_terms_is_an_error() -> None:
    w, u = _params()
    opt = MTAdam([w, u])
    opt.step(_toy(w, u))
    with pytest.raises(ValueError, match="2 loss terms before and 1 now"):
        opt.step(_toy(w, u)[:1])


def test_wrong_number_of_ranks_is_an_error() -> None:
    w, u = _params()
    with pytest.raises(ValueError, match="2 losses but 3 ranks"):
        MTAdam([w, u]).step(_toy(w, u), [1.0, 1.0, 1.0])


@pytest.mark.skipif(not torch.cuda.is_available(), reason="needs CUDA")
def test_cuda_matches_cpu() -> None:
    w, u = _params()
    wc, uc = (t.detach().cuda().requires_grad_() for t in (w, u))
    opt, opt_c = MTAdam([w, u]), MTAdam([wc, uc])
    for _ in range(3):
        opt.step(_toy(w, u))
        opt_c.step(_toy_cuda(wc, uc))
    assert opt_c.state[wc]["grad_norm"].device == wc.device
    torch.testing.assert_close(wc.cpu(), w.detach())


def _toy_cuda(w: torch.Tensor, u: torch.Tensor) -> list[torch.Tensor]:
    a, b = A.to(w.device), B.to(w.device)
    return [((w - a) ** 2).sum() + 3 * (u**2).sum(), 100 * (w * b).sum()]
